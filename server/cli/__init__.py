"""The command line: ``pendant`` (``main``), its slot editor (``slot``) and the analysis
commands (``analysis``)."""
