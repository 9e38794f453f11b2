"""Command-line apps, one per experiment (``python -m apps.<experiment>``, ``make
<experiment>``), all on the shared runner ``apps.runner``."""
