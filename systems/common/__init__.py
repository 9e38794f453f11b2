"""systems/common."""
