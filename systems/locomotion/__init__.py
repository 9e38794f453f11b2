"""systems/locomotion."""
