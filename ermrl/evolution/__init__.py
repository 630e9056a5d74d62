"""The outer loop ("evolution", paper §3): the Optuna study, the search space of Φ, the generation loop and the
robust selection of Φ*."""
