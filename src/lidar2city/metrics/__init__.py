"""Quality metrics: ground-filter errors, classification scores, geometric errors."""
