"""Host-side drivers: pure make_* commands, one async core per protocol, sync facades."""
