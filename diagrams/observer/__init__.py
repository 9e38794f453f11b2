"""diagrams/observer."""
