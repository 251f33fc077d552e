"""One module per vehicle the plant can be: each has `build(external) -> list[Behaviour]`, the
behaviours of that vehicle's nodes not in `external`, in the order they must be stepped."""
