"""Simulated device controllers.  Services talk to them through the same small driver
interfaces a real controller would implement, so a service never knows which it has."""
