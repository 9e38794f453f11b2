"""Flacco et al. (2016) experiments: residual comparison, push-and-comply, contact
localization, and the model refinement from the residuals (the paper's future work)."""
