"""The scanner's simulators: the FARO emulator, on a virtual bus in the scanner
service (its ``sim`` backend) or across a serial CAN link in a process of its own
(``faro-sim``), and its card. On a robot with a real scanner only the schema of the
emulator's faults (:mod:`.faults`) is loaded, which the scanner's config names for
the sim backend."""
