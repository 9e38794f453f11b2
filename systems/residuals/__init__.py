"""systems/residuals."""
