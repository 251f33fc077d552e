"""python-can's own test files run against the bench's bus and log format (scripts/python-can-suite).

Nothing here is collected by the bench's own test run: `plugin.py` is a pytest plugin the runner loads, and
`bench_mcap_test.py` is copied by the runner into python-can's `test/` package, next to the file it extends.
docs/python-can-conformance.md says what runs and why each skip is one.
"""
