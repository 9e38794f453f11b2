"""diagrams/station."""
