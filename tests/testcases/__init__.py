"""Unit tests of the project's test-case packages (testcases/): their oracles against the formula sheet."""
