"""The simulated nodes on the bench's clock: scheduler, stations, restbus and the behaviour API plants use."""
