"""The pytest plugin: the `bench` fixture's wiring, conformance markers, shards, the fixture reference."""
