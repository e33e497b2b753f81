//! The in-process server of the HTTP API and browser tests.
#![allow(dead_code)]

pub mod server;
