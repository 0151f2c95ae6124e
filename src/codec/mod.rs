//! TODO: codec layer (being built).
