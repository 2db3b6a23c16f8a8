"""The scanner service: the FARO scanner over the CAN automation interface."""
