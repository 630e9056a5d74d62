"""The paper's experiments built from the engine: the test phase (and later baselines and generalization)."""
