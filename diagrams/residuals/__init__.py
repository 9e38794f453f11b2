"""Flacco et al. (2016) experiments: residual comparison, push-and-comply, contact
localization."""
