//! The worker daemon against a real server on loopback, both in this process: one
//! integration-test binary, one file per concern.

mod cache;
mod common;
mod farm;
mod faults;
mod pilot;
mod pipeline;
