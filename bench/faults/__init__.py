"""Fault injection: the kinds (what each does to frames) and the plan of a run."""
