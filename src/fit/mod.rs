//! TODO: fit layer (being built).
