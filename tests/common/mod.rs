//! Shared by the tests that talk to a server from outside: HTTP (a client for well-formed
//! requests, raw sockets for malformed ones) and the in-process server.
#![allow(dead_code)]

pub mod http;
pub mod server;
pub mod vtu;
