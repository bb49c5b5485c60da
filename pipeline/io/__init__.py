"""Files in and out: point-cloud, depth and bag formats, captures, camera files, images,
length units, and the output-folder policy."""
