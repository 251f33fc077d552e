"""The record of a run (results.json): the model and its store."""
