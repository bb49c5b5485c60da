"""What people read: plain-text tables and the pictures of trials and experiments."""
