"""python-can's own test files run against the bench's bus and log format (scripts/python-can-suite).

Nothing here is collected by the bench's own test run: `plugin.py` is a pytest plugin the runner loads, and
`mcap_format.py` is copied by the runner into python-can's `test/` package as `bench_mcap_test.py`, next
to the file it extends (its name here keeps it out of the bench's own test run).
docs/python-can-conformance.md says what runs and why each skip is one.
"""
