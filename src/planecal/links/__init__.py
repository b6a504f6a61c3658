"""Robot-link and laser interfaces and their implementations (twin, FD11 UDP, ZS-LD80 serial)."""
