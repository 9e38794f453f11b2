"""The floating-base dynamic model (Flacco et al. 2016, eq. 9, Algorithms 1-2, eq. 13): a
fast implementation on Drake's kernels and the recursive reference implementation."""
