"""systems/simulation."""
