"""diagrams/locomotion."""
