"""Vehicle physics and reference ECUs that play DBC nodes on the bench.

Imports flow one way: `plant` may use `bench.sim.node` (the behaviour protocol) and nothing else of the
bench, and never pytest or reporting. The bench finds the plant through the entry point
`bench.plants: chassis = plant.factory:build`, and only through it: a vehicle is a module of this package's
plant/assemblies/ (plant/registry.py), and a plant from elsewhere registers an entry point of its own.
"""

import bench  # noqa: F401  (the bench's choice between a module's compiled and source form comes first)
