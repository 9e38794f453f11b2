"""Shared plumbing with no dependency on the rest of ``systems``: input and plant checks,
floating-base topology, 6-D spatial algebra, smoothing, and the one reader of Drake's contact
results."""
