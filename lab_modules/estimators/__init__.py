"""The estimators: Kalman filters (linear, extended, continuous-discrete) and other state
or parameter estimators, with the paper equations they implement.  They import plants at most."""
