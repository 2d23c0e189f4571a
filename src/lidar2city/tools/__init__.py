"""File-level jobs: read inputs, call algorithms, write outputs. One module per job."""
