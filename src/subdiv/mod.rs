//! TODO: subdiv layer (being built).
