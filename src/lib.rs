//! contact-sim: the job service on top of the numerical core ([`contact_core`]): routes
//! ([`app`], [`routes`]), job execution on a worker pool off the async runtime ([`jobs`]),
//! and the durable store ([`store`]: embedded SQLite, or PostgreSQL shared by many nodes).
#![forbid(unsafe_code)]

pub mod app;
pub mod auth;
pub mod config;
pub mod continuation;
pub mod disk;
pub mod jobs;
pub mod json_body;
pub mod lease;
pub mod limits;
pub mod meshes;
pub mod problem;
pub mod routes;
pub mod server;
pub mod state;
pub mod store;
pub mod stream;
pub mod submission;
pub mod tls;

pub use config::Config;
