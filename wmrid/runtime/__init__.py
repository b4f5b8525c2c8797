"""The process's runtime, apart from the domain: Ctrl-C kept out of numba's compiler (signals), atomic outputs, the
memory
budget and the allocator's tuning, and files the user did not name read with care."""
