//! Tessera's wire types. Every JSON shape exchanged between the CLI, the server and the
//! workers is defined here once, as serde types (filled by the farm issues).
#![warn(missing_docs)]
