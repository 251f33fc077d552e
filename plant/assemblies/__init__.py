"""The vehicles the plant can be: one module per vehicle, each declaring it as `VEHICLE` (plant/declaration.py).
plant/registry.py discovers them; nothing lists them by hand. Modules from a `plant/assemblies/` folder elsewhere on
the import path count too (extend_path)."""

from pkgutil import extend_path

__path__ = extend_path(__path__, __name__)
