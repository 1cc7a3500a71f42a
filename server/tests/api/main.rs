//! The server's HTTP tests: a real server on 127.0.0.1:0 and simulated workers that render
//! real tiles with the tracer. One binary, one file per concern.

mod auth;
mod bad_input;
mod common;
mod contract;
mod dashboard;
mod denoise;
mod farm;
mod faults;
mod openapi;
mod video;
mod waiting;
mod webhooks;
