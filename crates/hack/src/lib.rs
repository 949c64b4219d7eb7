//! No code: this crate only turns on features of shared dependencies (its Cargo.toml says
//! which and why), so that the test build and the Python module's build compile the core once.
