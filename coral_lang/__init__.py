"""The CORAL language: mission text to a Petri net, checked against a vehicle profile."""
