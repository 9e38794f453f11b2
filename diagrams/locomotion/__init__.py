"""The walking Nao (ZMP preview control) and its walking metrics."""
