"""Vehicle physics and reference ECUs that play DBC nodes on the bench.

Imports flow one way: `plant` may use `bench.node` (the behaviour protocol) and nothing else of the
bench, and never pytest or reporting. The bench finds the plant through the entry point
`bench.plants: chassis = plant.factory:build`.

The package path is extended (pkgutil.extend_path) so that a `plant/assemblies/` folder in another directory on
the import path adds its vehicles to this plant (plant/registry.py), e.g. a project's own vehicle or a test's.
"""

from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)
