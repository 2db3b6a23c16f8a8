"""The simulated world: the one owner of ground truth and of the sim clock."""
