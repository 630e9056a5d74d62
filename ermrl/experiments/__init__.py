"""The paper's experiments built from the engine: the test phase, baselines and normalized scores, generalization, and the named experiments."""
