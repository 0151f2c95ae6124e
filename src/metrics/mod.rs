//! TODO: metrics layer (being built).
