"""diagrams/residuals."""
