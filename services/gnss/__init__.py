"""The gnss service: GNSS receivers (two antennas) and the GNSS compass."""
