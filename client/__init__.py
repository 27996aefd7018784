"""The robot side of fleetcal: a client of its HTTP API (`fleetcal upload`, `profiles`, `runs`)."""
