"""IR-MCL neural occupancy field: model, rendering, training data."""
