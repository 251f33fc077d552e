"""The run log: MCAP files that Foxglove opens as they are, written while a run goes on and read back after it.

- format: the topics, schemas and JSON text of the records (the one place that says what a log holds);
- recorder: the writer (mcap's public Writer; mcapfast, its checked fast path, when the installed mcap allows);
- logproc: the writer in a child process, fed by the run in batches;
- logread: reading a log back, also a killed run's;
- canio: the format as a python-can log format (".mcap" reader and writer, registered by entry points), and the
  one conversion of a logged frame into a `can.Message`.

Importing this package imports none of them (the run's own process needs neither mcap nor cantools' encoders
for its log: bench.log.logproc's parent side imports nothing heavy).
"""
