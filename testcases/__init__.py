"""HIL test cases of the chassis bench (run with `bench run`); 4WIS oracle and helpers live beside them."""
