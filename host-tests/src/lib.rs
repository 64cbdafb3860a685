//! Host-side helpers shared by the tests and the evaluation binaries.
