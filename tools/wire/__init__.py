"""Stand-ins for the outside world on the Unity wire: the simulator client, the server launcher, frame sources."""
