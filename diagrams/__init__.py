"""Diagram builders, one module per experiment (named as its app and make target), each
taking a scenario dataclass (``diagrams.scenarios``) and returning the diagram and the
handles a caller needs; the metrics that read a diagram's loggers live beside it. Diagrams
import systems and models, never apps."""
