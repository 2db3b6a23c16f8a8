"""The nav service: EKF localization and route following."""
