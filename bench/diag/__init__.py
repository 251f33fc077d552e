"""Diagnostics: UDS (ISO 14229-1) on ISO-TP (ISO 15765-2): the declaration, the simulated nodes' servers and the
bench's tester."""
