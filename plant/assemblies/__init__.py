"""The vehicles the plant can be: one module per vehicle, each declaring it as `VEHICLE` (plant/declaration.py).
plant/registry.py discovers them; nothing lists them by hand."""
