//! The accept loop: every connection bounded in number and time, optionally over TLS.
//!
//! `axum::serve` exposes none of these bounds, so connections are served here with hyper directly:
//!
//! * at most `max_connections` at once — beyond it the loop stops accepting (new connections wait
//!   in the kernel's backlog and cost no file descriptor) until one closes;
//! * at most `max_per_client` of them from one client (`PerClient`; an IPv4 address or an IPv6
//!   /64, [`ClientKey`]): a further connection from it is answered 429 and closed at once, so that
//!   one client holding half-open connections cannot take the slots every other client needs;
//!   every request carries its client's key (a request extension), for the budgets the API
//!   shares out per client;
//! * a TLS handshake and the request head must arrive within `header_timeout` (hyper's
//!   `header_read_timeout`, which also closes keep-alive connections idle for that long);
//! * a response that cannot be sent for `send_timeout` — the client stopped reading it — closes
//!   the connection ([`SendTimeout`]): a client cannot hold a connection by never reading an event
//!   stream. Only a stalled send counts, so a request that computes for a while is not cut off;
//! * request bodies are bounded in time by the extractors (`--body-timeout`), in size by the body
//!   limits;
//! * on shutdown, connections finish their current request and close
//!   ([`hyper_util::server::graceful`]), for at most [`GRACE`].

use std::collections::HashMap;
use std::future::Future;
use std::io;
use std::pin::Pin;
use std::sync::{Arc, Mutex};
use std::task::{Context, Poll};
use std::time::Duration;

use hyper::body::Incoming;
use hyper::server::conn::http1;
use hyper_util::rt::{TokioIo, TokioTimer};
use hyper_util::server::graceful::{GracefulShutdown, Watcher};
use hyper_util::service::TowerToHyperService;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::net::TcpListener;
use tokio::sync::Semaphore;
use tokio::time::Sleep;
use tokio_rustls::TlsAcceptor;

use crate::jobs::merges::shares::ClientKey;

/// Longest wait for open connections to finish after a shutdown began.
pub const GRACE: Duration = Duration::from_secs(10);

/// The per-connection bounds.
#[derive(Debug, Clone, Copy)]
pub struct ConnectionLimits {
    /// Most connections open at once.
    pub max_connections: usize,
    /// Most connections open at once from one client address.
    pub max_per_client: usize,
    /// A request head (and a TLS handshake) must arrive within this; keep-alive connections idle
    /// this long are closed.
    pub header_timeout: Duration,
    /// A response the client does not read for this long closes its connection.
    pub send_timeout: Duration,
}

impl Default for ConnectionLimits {
    fn default() -> Self {
        Self {
            max_connections: 512,
            // Half: another client always finds half the slots; 100 keep-alive clients behind one
            // address (a load test, a small proxy) stay within it.
            max_per_client: 256,
            header_timeout: Duration::from_secs(10),
            send_timeout: Duration::from_secs(60),
        }
    }
}

/// Serves `app` on `listener` until `shutdown` resolves, then lets open connections finish (for at
/// most [`GRACE`]).
pub async fn serve(
    listener: TcpListener,
    app: axum::Router,
    tls: Option<TlsAcceptor>,
    limits: ConnectionLimits,
    shutdown: impl Future<Output = ()>,
) {
    let permits = Arc::new(Semaphore::new(limits.max_connections));
    let clients = Arc::new(PerClient { open: Mutex::new(HashMap::new()), limit: limits.max_per_client });
    let graceful = GracefulShutdown::new();
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let permit = tokio::select! {
            permit = permits.clone().acquire_owned() => permit.expect("the semaphore is never closed"),
            _ = &mut shutdown => break,
        };
        let (stream, peer) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(accepted) => accepted,
                Err(e) => {
                    // Out of file descriptors or a connection reset before accept: not fatal.
                    tracing::warn!(error = %e, "accept failed");
                    tokio::time::sleep(Duration::from_millis(50)).await;
                    continue;
                }
            },
            _ = &mut shutdown => break,
        };
        let key = ClientKey::of(peer.ip());
        let Some(client) = clients.admit(key) else {
            // Best effort, without waiting: the client learns why (a TLS client sees a closed
            // connection), and the slot is free again at once.
            let _ = stream.try_write(OVER_SHARE);
            drop(permit);
            continue;
        };
        let _ = stream.set_nodelay(true);
        let app = app.clone();
        let tls = tls.clone();
        let watcher = graceful.watcher();
        tokio::spawn(async move {
            let _permit = (permit, client);
            let io = SendTimeout::new(stream, limits.send_timeout);
            match tls {
                None => serve_connection(io, app, key, watcher, limits).await,
                Some(acceptor) => match tokio::time::timeout(limits.header_timeout, acceptor.accept(io)).await {
                    Ok(Ok(tls_stream)) => serve_connection(tls_stream, app, key, watcher, limits).await,
                    Ok(Err(e)) => tracing::debug!(error = %e, "TLS handshake failed"),
                    Err(_) => tracing::debug!("TLS handshake timed out"),
                },
            }
        });
    }
    drop(listener);
    if tokio::time::timeout(GRACE, graceful.shutdown()).await.is_err() {
        tracing::warn!("connections still open {} s after shutdown began; closing them", GRACE.as_secs());
    }
}

/// The answer to a connection beyond its client's share.
const OVER_SHARE: &[u8] = b"HTTP/1.1 429 Too Many Requests\r\nRetry-After: 1\r\nConnection: close\r\n\
Content-Type: text/plain\r\nContent-Length: 70\r\n\r\ntoo many connections from this address (--max-connections-per-client)\n";

/// Connections open per client.
struct PerClient {
    /// std Mutex: map operations only.
    open: Mutex<HashMap<ClientKey, usize>>,
    limit: usize,
}

/// One admitted connection of a client; gives its place back when dropped.
struct ClientSlot {
    clients: Arc<PerClient>,
    ip: ClientKey,
}

impl PerClient {
    /// A place for one more connection from `ip`, if it has fewer than its share open (IPv4 seen
    /// as IPv6 counts as the IPv4 address; IPv6 addresses of one /64 as one client).
    fn admit(self: &Arc<Self>, ip: ClientKey) -> Option<ClientSlot> {
        let mut open = self.open.lock().expect("per-client counts");
        let n = open.entry(ip).or_insert(0);
        if *n >= self.limit {
            return None;
        }
        *n += 1;
        Some(ClientSlot { clients: self.clone(), ip })
    }
}

impl Drop for ClientSlot {
    fn drop(&mut self) {
        let mut open = self.clients.open.lock().expect("per-client counts");
        if let Some(n) = open.get_mut(&self.ip) {
            *n -= 1;
            if *n == 0 {
                open.remove(&self.ip);
            }
        }
    }
}

async fn serve_connection<I>(io: I, app: axum::Router, client: ClientKey, watcher: Watcher, limits: ConnectionLimits)
where
    I: AsyncRead + AsyncWrite + Unpin + Send + 'static,
{
    // Every request of the connection says whose it is.
    let app = tower::ServiceExt::map_request(app, move |mut request: axum::extract::Request<Incoming>| {
        request.extensions_mut().insert(client);
        request
    });
    let service = TowerToHyperService::new(app);
    let mut builder = http1::Builder::new();
    builder.timer(TokioTimer::new()).header_read_timeout(limits.header_timeout).keep_alive(true);
    let connection = builder.serve_connection(TokioIo::new(io), service);
    if let Err(e) = watcher.watch(connection).await {
        tracing::debug!(error = %e, "connection ended with an error");
    }
}

/// A stream whose writes fail with `TimedOut` once a write has waited `limit` without progress
/// (the peer's receive window stayed full: it stopped reading). Reads are passed through: how long
/// a client may take to send is bounded elsewhere (the header and body timeouts), and a request
/// that computes before it answers sends nothing meanwhile without being stalled.
pub struct SendTimeout<IO> {
    io: IO,
    limit: Duration,
    /// Armed when a write first returns `Pending`, disarmed by any progress.
    stalled_since: Option<Pin<Box<Sleep>>>,
}

impl<IO> SendTimeout<IO> {
    /// Wraps `io`, failing a write that made no progress for `limit`.
    pub fn new(io: IO, limit: Duration) -> Self {
        Self { io, limit, stalled_since: None }
    }

    /// A write made progress (or completed): the stall clock stops.
    fn progressed(&mut self) {
        self.stalled_since = None;
    }

    /// A write is pending: start the stall clock (once) and see whether it has run out.
    fn stalled(&mut self, cx: &mut Context<'_>) -> Poll<io::Error> {
        let limit = self.limit;
        let deadline = self.stalled_since.get_or_insert_with(|| Box::pin(tokio::time::sleep(limit)));
        match deadline.as_mut().poll(cx) {
            Poll::Ready(()) => Poll::Ready(io::Error::new(io::ErrorKind::TimedOut, "the client stopped reading")),
            Poll::Pending => Poll::Pending,
        }
    }
}

impl<IO: AsyncRead + Unpin> AsyncRead for SendTimeout<IO> {
    fn poll_read(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &mut ReadBuf<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl<IO: AsyncWrite + Unpin> AsyncWrite for SendTimeout<IO> {
    fn poll_write(mut self: Pin<&mut Self>, cx: &mut Context<'_>, buf: &[u8]) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.io).poll_write(cx, buf) {
            Poll::Pending => self.stalled(cx).map(Err),
            done => {
                self.progressed();
                done
            }
        }
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        match Pin::new(&mut self.io).poll_flush(cx) {
            Poll::Pending => self.stalled(cx).map(Err),
            done => {
                self.progressed();
                done
            }
        }
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.io).poll_shutdown(cx)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        match Pin::new(&mut self.io).poll_write_vectored(cx, bufs) {
            Poll::Pending => self.stalled(cx).map(Err),
            done => {
                self.progressed();
                done
            }
        }
    }

    fn is_write_vectored(&self) -> bool {
        self.io.is_write_vectored()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test(start_paused = true)]
    async fn a_send_to_a_reader_that_stopped_times_out_and_waiting_to_read_does_not() {
        let (mut client, server) = tokio::io::duplex(1024);
        let mut server = SendTimeout::new(server, Duration::from_secs(60));
        // The client sends nothing for ten minutes (virtual time): a read just waits.
        let mut byte = [0u8];
        let read = tokio::time::timeout(Duration::from_secs(600), server.read_exact(&mut byte)).await;
        assert!(read.is_err(), "reads never time out here");
        // A reader that keeps up: 3 KiB through a 1 KiB pipe, read 30 s apart.
        let writer = async {
            server.write_all(&[7u8; 3072]).await.unwrap();
            server
        };
        let reader = async {
            let mut sink = [0u8; 1024];
            for _ in 0..3 {
                tokio::time::sleep(Duration::from_secs(30)).await;
                client.read_exact(&mut sink).await.unwrap();
            }
            client
        };
        let (mut server, _client) = tokio::join!(writer, reader);
        // A reader that stopped: the pipe fills, and the write fails 60 s later.
        let err = server.write_all(&[7u8; 4096]).await.unwrap_err();
        assert_eq!(err.kind(), io::ErrorKind::TimedOut);
    }
}
