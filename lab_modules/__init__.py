"""Physics, estimators, controllers and exercises of the AMB estimation lab."""
