"""Jobs: analyses and JSON restores run by worker processes (``worker``), and what each
kind of job does (``kinds``)."""
