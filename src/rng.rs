//! NumPy-compatible random numbers (SeedSequence, PCG64, Generator.uniform).
