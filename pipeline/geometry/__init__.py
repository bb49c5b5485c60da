"""Small geometric building blocks every layer uses: poses and the taxel layout of a pad."""
