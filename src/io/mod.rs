//! TODO: io layer (being built).
