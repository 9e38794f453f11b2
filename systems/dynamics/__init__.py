"""systems/dynamics."""
