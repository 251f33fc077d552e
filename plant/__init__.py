"""Vehicle physics and reference ECUs that play DBC nodes on the bench.

Imports flow one way: `plant` may use `bench.node` (the behaviour protocol) and nothing else of the
bench, and never pytest or reporting. The bench finds the plant through the entry point
`bench.plants: chassis = plant.factory:build`.
"""
