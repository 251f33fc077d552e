"""The databases: the codec over cantools and the checks of `bench dbc check`."""
