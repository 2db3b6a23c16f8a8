"""The scanner's simulators: the FARO emulator, on a virtual bus in the scanner
service (its ``sim`` backend) or across a serial CAN link in a process of its own
(``faro-sim``), and its card. None of it is loaded on a robot with a real scanner;
the scanner's config names the emulator's faults (:mod:`.faults`) for the sim
backend."""
