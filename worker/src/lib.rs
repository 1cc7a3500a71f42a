//! Tessera's worker daemon (lease, fetch scene, render, upload, heartbeat). Filled by the
//! worker issue.
