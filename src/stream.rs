//! Streaming responses produced by blocking code: a `Write` that forwards chunks to the HTTP
//! body, so large fields (JSON, VTU, archives) are never built whole in memory and the
//! rendering runs on the blocking pool, not on the async runtime's threads.

use crate::problem::Problem;
use axum::body::{Body, Bytes};
use axum::http::{header, HeaderValue, Method};
use axum::response::Response;
use std::io::{self, Write};
use tokio::sync::mpsc;

struct ChannelWriter {
    tx: mpsc::Sender<Result<Bytes, io::Error>>,
}

impl Write for ChannelWriter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.tx
            .blocking_send(Ok(Bytes::copy_from_slice(buf)))
            .map_err(|_| io::Error::new(io::ErrorKind::BrokenPipe, "client went away"))?;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// A response whose body is written by `render` on a blocking thread.
pub fn blocking_body(
    content_type: &'static str,
    render: impl FnOnce(&mut dyn Write) -> io::Result<()> + Send + 'static,
) -> Response {
    let (tx, mut rx) = mpsc::channel::<Result<Bytes, io::Error>>(8);
    tokio::task::spawn_blocking(move || {
        let err_tx = tx.clone();
        let mut w = io::BufWriter::with_capacity(64 * 1024, ChannelWriter { tx });
        let r = render(&mut w).and_then(|_| w.flush());
        if let Err(e) = r {
            if e.kind() != io::ErrorKind::BrokenPipe {
                // Abort the body: the client sees a truncated transfer, not a silent success.
                let _ = err_tx.blocking_send(Err(e));
            }
        }
    });
    let stream = futures_util::stream::poll_fn(move |cx| rx.poll_recv(cx));
    let mut resp = Response::new(Body::from_stream(stream));
    resp.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    resp
}

/// Counts the bytes written to it, keeping none.
struct Counter(u64);

impl Write for Counter {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0 += buf.len() as u64;
        Ok(buf.len())
    }

    fn flush(&mut self) -> io::Result<()> {
        Ok(())
    }
}

/// The number of bytes `render` writes, keeping none (blocking: it runs `render`).
pub fn rendered_len(render: impl FnOnce(&mut dyn Write) -> io::Result<()>) -> io::Result<u64> {
    let mut counter = Counter(0);
    render(&mut counter)?;
    Ok(counter.0)
}

/// [`blocking_body`] for GET; for HEAD the same headers with the body's length
/// (`Content-Length`, counted by running `render` on a blocking thread into a counter) and no
/// body, so a client can say how large a download is before fetching it.
pub async fn blocking_body_or_length(
    method: &Method,
    content_type: &'static str,
    render: impl FnOnce(&mut dyn Write) -> io::Result<()> + Send + 'static,
) -> Result<Response, Problem> {
    if method != Method::HEAD {
        return Ok(blocking_body(content_type, render));
    }
    let bytes = tokio::task::spawn_blocking(move || rendered_len(render))
        .await
        .map_err(|e| Problem::internal(format!("rendering task failed: {e}")))?
        .map_err(|e| Problem::internal(e.to_string()))?;
    let mut resp = Response::new(Body::empty());
    let h = resp.headers_mut();
    h.insert(header::CONTENT_TYPE, HeaderValue::from_static(content_type));
    h.insert(header::CONTENT_LENGTH, HeaderValue::from(bytes));
    Ok(resp)
}
