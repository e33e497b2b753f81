//! The HTTP/1.1 accept loop: hyper with a timer, so that a client that does not send a
//! complete request head within `header_timeout` (a slow-loris client, or a connection
//! opened and left silent) is disconnected instead of holding a connection — and a file
//! descriptor — forever. (`axum::serve` sets no timer, which silently disables hyper's
//! header read timeout.) Each request carries the peer address as
//! `ConnectInfo<SocketAddr>` (per-client limits). On shutdown the listener stops accepting,
//! every connection finishes its current request, and the call returns once all are closed.
//!
//! With a TLS acceptor (`serve --tls-cert`, see `crate::tls`) each connection first completes
//! a TLS handshake in its own task, within the same `header_timeout`; a client that does not
//! speak TLS (plain HTTP to the HTTPS port) fails the handshake, gets rustls' alert and is
//! disconnected, logged at debug level only (it is the client's mistake, and per-connection
//! noise at a higher level would let anyone fill the log).

use axum::extract::ConnectInfo;
use axum::Router;
use hyper::body::Incoming;
use hyper_util::rt::{TokioIo, TokioTimer};
use std::future::Future;
use std::pin::pin;
use std::time::Duration;
use tower_service::Service;

/// Serves `app` on `listener` (HTTPS with `tls`) until `shutdown` resolves, then drains the
/// connections.
pub async fn run(
    listener: tokio::net::TcpListener,
    app: Router,
    header_timeout: Duration,
    tls: Option<tokio_rustls::TlsAcceptor>,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    let mut builder = hyper::server::conn::http1::Builder::new();
    builder
        .timer(TokioTimer::new())
        .header_read_timeout(header_timeout);
    // Connection tasks hold a receiver; the sender's `closed()` resolves when all are gone.
    let (close_tx, close_rx) = tokio::sync::watch::channel(());
    let (stop_tx, stop_rx) = tokio::sync::watch::channel(false);
    let mut shutdown = pin!(shutdown);
    loop {
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(a) => a,
                Err(_) => {
                    // Out of file descriptors and the like: back off, keep serving.
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            _ = &mut shutdown => break,
        };
        let _ = stream.set_nodelay(true);
        let router = app.clone();
        let service = hyper::service::service_fn(move |mut req: hyper::Request<Incoming>| {
            req.extensions_mut().insert(ConnectInfo(peer));
            // A Router is always ready: `call` without `poll_ready` is allowed.
            let mut router = router.clone();
            router.call(req)
        });
        let mut stop = stop_rx.clone();
        let close = close_rx.clone();
        let Some(acceptor) = tls.clone() else {
            let conn = builder.serve_connection(TokioIo::new(stream), service);
            tokio::spawn(drive(conn, stop, close));
            continue;
        };
        let builder = builder.clone();
        tokio::spawn(async move {
            let handshake = tokio::time::timeout(header_timeout, acceptor.accept(stream));
            let stream = tokio::select! {
                done = handshake => match done {
                    Ok(Ok(stream)) => stream,
                    Ok(Err(e)) => {
                        tracing::debug!("TLS handshake with {peer} failed: {e}");
                        return;
                    }
                    Err(_) => {
                        tracing::debug!("TLS handshake with {peer} timed out");
                        return;
                    }
                },
                _ = stop.wait_for(|s| *s) => return,
            };
            let conn = builder.serve_connection(TokioIo::new(stream), service);
            drive(conn, stop, close).await;
        });
    }
    drop(listener);
    drop(close_rx);
    let _ = stop_tx.send(true);
    close_tx.closed().await;
    Ok(())
}

/// Runs one connection to its end; once `stop` turns true it finishes the current request
/// and closes. Dropping `close` tells the accept loop this connection is gone.
async fn drive<I, S, B>(
    conn: hyper::server::conn::http1::Connection<I, S>,
    mut stop: tokio::sync::watch::Receiver<bool>,
    close: tokio::sync::watch::Receiver<()>,
) where
    I: hyper::rt::Read + hyper::rt::Write + Unpin,
    S: hyper::service::HttpService<Incoming, ResBody = B>,
    S::Error: Into<Box<dyn std::error::Error + Send + Sync>>,
    B: hyper::body::Body + 'static,
    B::Error: Into<Box<dyn std::error::Error + Send + Sync>>,
{
    let mut conn = pin!(conn);
    let mut stopping = false;
    loop {
        tokio::select! {
            _ = conn.as_mut() => break,
            _ = stop.wait_for(|s| *s), if !stopping => {
                stopping = true;
                conn.as_mut().graceful_shutdown();
            }
        }
    }
    drop(close);
}
