"""The closed loops: compiled simulations of plant, sensors, estimator and controller, and the
experiment classes that set them up and run them.  They import plants, estimators and controllers."""
