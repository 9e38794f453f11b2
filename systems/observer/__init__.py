"""systems/observer."""
