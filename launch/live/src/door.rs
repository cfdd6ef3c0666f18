//! The live server's door. Viewers connect here; each connection is relayed, message by message,
//! to the Foxglove SDK's server listening on loopback. The door does two things the SDK does not:
//!
//! * **It takes every name of the protocol.** The SDK accepts the subprotocols `foxglove.sdk.v1`
//!   and `foxglove.sdk.v1.1` only; the same messages were named `foxglove.websocket.v1` before
//!   (older Foxglove, Lichtblick, PlotJuggler's bridge client). A client that offers only that
//!   name is answered under it and relayed to the SDK as `foxglove.sdk.v1`. Nothing of the
//!   protocol's messages is read or changed.
//! * **It counts what a slow client loses.** Each client has an outbox of at most [`OUTBOX`]
//!   messages; the server's messages are read from loopback as they come and queued there. When
//!   it is full, the oldest binary message (the run's data and time broadcasts) goes, counted; a
//!   client whose outbox is full of text messages (the protocol's control messages) is let go,
//!   as the SDK lets go a client whose control queue is full. The run never waits for a client.
//!
//! Every wait is bounded: a connection has [`HANDSHAKE`] to finish its WebSocket handshake (and
//! the relay as long to reach the server), at most [`MAX_CONNECTIONS`] are open at once, and a
//! message is at most [`MAX_MESSAGE`]. When every place is taken, a new connection takes the
//! place of the oldest one whose client has said nothing since it connected (a viewer
//! subscribes at once; a client that holds a connection and never speaks is not a viewer); when
//! every client has spoken, the new connection is closed. So idle connections, however many,
//! never keep a viewer out.

use std::collections::VecDeque;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError};
use std::time::Duration;

use futures_util::{SinkExt as _, StreamExt as _};
use tokio::net::{TcpListener, TcpStream};
use tokio::sync::{Notify, Semaphore};
use tokio_tungstenite::tungstenite::client::IntoClientRequest as _;
use tokio_tungstenite::tungstenite::handshake::server::{ErrorResponse, Request, Response};
use tokio_tungstenite::tungstenite::http::{header, HeaderValue, StatusCode};
use tokio_tungstenite::tungstenite::protocol::WebSocketConfig;
use tokio_tungstenite::tungstenite::Message;

/// The subprotocol names the door answers, most preferred first, each with the name the SDK's
/// server is asked for.
pub const SUBPROTOCOLS: [(&str, &str); 3] = [
    ("foxglove.sdk.v1.1", "foxglove.sdk.v1.1"),
    ("foxglove.sdk.v1", "foxglove.sdk.v1"),
    ("foxglove.websocket.v1", "foxglove.sdk.v1"),
];

/// Messages a client's outbox holds at most (the SDK's own per-client backlog).
pub const OUTBOX: usize = 1024;
/// The SDK's backlog toward the door, which reads it as it comes: it never fills, so that every
/// message a slow client loses is lost (and counted) in its outbox.
pub const UPSTREAM_BACKLOG: usize = 1 << 16;
/// How long a connection may take to finish its handshake.
pub const HANDSHAKE: Duration = Duration::from_secs(2);
/// Connections open at once, at most.
pub const MAX_CONNECTIONS: usize = 64;
/// The largest message either way (a subscription of every topic is a few KiB).
pub const MAX_MESSAGE: usize = 1 << 20;

/// The subprotocol the door answers a client that offers `offered` (the values of its
/// `Sec-WebSocket-Protocol` headers), and the one it asks the SDK's server for.
pub fn choose<'a>(
    offered: impl IntoIterator<Item = &'a str>,
) -> Option<(&'static str, &'static str)> {
    let names: Vec<&str> = offered
        .into_iter()
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    SUBPROTOCOLS
        .into_iter()
        .find(|(name, _)| names.contains(name))
}

/// What [`Outbox::push`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pushed {
    /// Queued.
    Queued,
    /// Queued; the oldest binary message went to make room (or this one, if none is queued).
    DroppedOne,
    /// The outbox is full of text messages: the client is let go.
    Full,
}

/// A client's outbox (see the module's description).
#[derive(Debug, Default)]
pub struct Outbox {
    queue: VecDeque<Message>,
    /// The server's side ended: what is queued is the last.
    ended: bool,
}

impl Outbox {
    /// Queues `m`, making room as the module's description says.
    pub fn push(&mut self, m: Message) -> Pushed {
        if self.queue.len() < OUTBOX {
            self.queue.push_back(m);
            return Pushed::Queued;
        }
        match self.queue.iter().position(Message::is_binary) {
            Some(i) => {
                self.queue.remove(i);
                self.queue.push_back(m);
                Pushed::DroppedOne
            }
            None if m.is_binary() => Pushed::DroppedOne,
            None => Pushed::Full,
        }
    }

    /// The next message to send.
    pub fn pop(&mut self) -> Option<Message> {
        self.queue.pop_front()
    }

    /// How many are queued.
    pub fn len(&self) -> usize {
        self.queue.len()
    }

    /// Whether none is queued.
    pub fn is_empty(&self) -> bool {
        self.queue.is_empty()
    }
}

/// What the door counted.
#[derive(Debug, Default)]
pub struct Counts {
    /// Connections open now.
    pub open: AtomicU64,
    /// Binary messages (the run's data, time broadcasts) dropped from slow clients' outboxes.
    pub dropped: AtomicU64,
    /// Clients let go: outbox full of control messages, or a connection over the limit.
    pub let_go: AtomicU64,
    /// Connections relayed to the SDK's server (its handshake there done).
    pub relayed: AtomicU64,
}

/// One open connection, as the door keeps it.
#[derive(Debug, Default)]
struct Connection {
    /// Its client sent a message since its handshake (a viewer subscribes at once).
    spoke: std::sync::atomic::AtomicBool,
    /// Raised to close it (its place is taken by a new connection).
    evict: Notify,
}

/// The open connections, oldest first.
type Open = Mutex<VecDeque<(u64, Arc<Connection>)>>;

/// How long a new connection waits for the place of the connection it evicted.
const EVICTED_WITHIN: Duration = Duration::from_secs(1);

/// Serves connections on `listener`, each relayed to the SDK's server at `upstream`, until the
/// runtime it runs on is shut down.
pub async fn serve(listener: TcpListener, upstream: SocketAddr, counts: Arc<Counts>) {
    let slots = Arc::new(Semaphore::new(MAX_CONNECTIONS));
    let open: Arc<Open> = Arc::default();
    for n in 0u64.. {
        let Ok((stream, _)) = listener.accept().await else {
            // A failed accept (e.g. out of descriptors): try again a little later.
            tokio::time::sleep(Duration::from_millis(10)).await;
            continue;
        };
        let counts = counts.clone();
        let (slots, open) = (slots.clone(), open.clone());
        tokio::spawn(async move {
            let slot = match slots.clone().try_acquire_owned() {
                Ok(slot) => slot,
                Err(_) => {
                    // Full: the place of the oldest connection that never spoke, if any.
                    if !evict_silent(&open) {
                        counts.let_go.fetch_add(1, Ordering::Relaxed);
                        return;
                    }
                    match tokio::time::timeout(EVICTED_WITHIN, slots.acquire_owned()).await {
                        Ok(Ok(slot)) => slot,
                        _ => {
                            counts.let_go.fetch_add(1, Ordering::Relaxed);
                            return;
                        }
                    }
                }
            };
            let me = Arc::new(Connection::default());
            lock(&open).push_back((n, me.clone()));
            counts.open.fetch_add(1, Ordering::Relaxed);
            tokio::select! {
                () = relay(stream, upstream, &counts, &me.spoke) => {}
                () = me.evict.notified() => {
                    counts.let_go.fetch_add(1, Ordering::Relaxed);
                }
            }
            lock(&open).retain(|(k, _)| *k != n);
            counts.open.fetch_sub(1, Ordering::Relaxed);
            drop(slot);
        });
    }
}

fn lock<T>(m: &Mutex<T>) -> std::sync::MutexGuard<'_, T> {
    m.lock().unwrap_or_else(PoisonError::into_inner)
}

/// Closes the oldest open connection whose client never spoke; whether there was one.
fn evict_silent(open: &Open) -> bool {
    let mut open = lock(open);
    let Some(i) = open
        .iter()
        .position(|(_, c)| !c.spoke.load(Ordering::Relaxed))
    else {
        return false;
    };
    if let Some((_, c)) = open.remove(i) {
        c.evict.notify_one();
    }
    true
}

fn config() -> WebSocketConfig {
    WebSocketConfig::default()
        .max_message_size(Some(MAX_MESSAGE))
        .max_frame_size(Some(MAX_MESSAGE))
}

/// One client's connection, from its handshake to its end; `spoke` is raised once its client
/// sends a message.
async fn relay(
    stream: TcpStream,
    upstream: SocketAddr,
    counts: &Counts,
    spoke: &std::sync::atomic::AtomicBool,
) {
    let _ = stream.set_nodelay(true);
    let mut chosen = None;
    // The callback's type is tungstenite's (its refusal is an HTTP response).
    #[allow(clippy::result_large_err)]
    let answer = |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
        let offered = req
            .headers()
            .get_all(header::SEC_WEBSOCKET_PROTOCOL)
            .iter()
            .filter_map(|v| v.to_str().ok());
        let Some((name, up)) = choose(offered) else {
            let names: Vec<&str> = SUBPROTOCOLS.iter().map(|(n, _)| *n).collect();
            let mut refusal = ErrorResponse::new(Some(format!(
                "offer one of the subprotocols {}\n",
                names.join(", ")
            )));
            *refusal.status_mut() = StatusCode::BAD_REQUEST;
            return Err(refusal);
        };
        resp.headers_mut().insert(
            header::SEC_WEBSOCKET_PROTOCOL,
            HeaderValue::from_static(name),
        );
        chosen = Some(up);
        Ok(resp)
    };
    let accepted = tokio::time::timeout(
        HANDSHAKE,
        tokio_tungstenite::accept_hdr_async_with_config(stream, answer, Some(config())),
    )
    .await;
    // A handshake that failed, timed out or offered no name of the protocol ends here.
    let (Ok(Ok(client)), Some(up)) = (accepted, chosen) else {
        return;
    };
    let Some(server) = connect(upstream, up).await else {
        return;
    };
    counts.relayed.fetch_add(1, Ordering::Relaxed);
    pipe(client, server, counts, spoke).await;
}

/// The relay's connection to the SDK's server, asking for subprotocol `name`.
async fn connect(
    upstream: SocketAddr,
    name: &'static str,
) -> Option<tokio_tungstenite::WebSocketStream<TcpStream>> {
    let mut request = format!("ws://{upstream}/").into_client_request().ok()?;
    request.headers_mut().insert(
        header::SEC_WEBSOCKET_PROTOCOL,
        HeaderValue::from_static(name),
    );
    let connected = tokio::time::timeout(HANDSHAKE, async {
        let tcp = TcpStream::connect(upstream).await.ok()?;
        let _ = tcp.set_nodelay(true);
        tokio_tungstenite::client_async_with_config(request, tcp, Some(config()))
            .await
            .ok()
    })
    .await;
    connected.ok().flatten().map(|(ws, _)| ws)
}

/// Relays a connected client and its connection to the server until either side ends.
async fn pipe(
    client: tokio_tungstenite::WebSocketStream<TcpStream>,
    server: tokio_tungstenite::WebSocketStream<TcpStream>,
    counts: &Counts,
    spoke: &std::sync::atomic::AtomicBool,
) {
    let (mut to_client, mut from_client) = client.split();
    let (mut to_server, mut from_server) = server.split();
    let outbox = Mutex::new(Outbox::default());
    let ready = Notify::new();
    // Raised when the client is let go: the connection ends at once, unsent messages with it.
    let cut = Notify::new();
    let lock = || outbox.lock().unwrap_or_else(PoisonError::into_inner);
    // The server's messages, queued as they come.
    let down = async {
        while let Some(Ok(m)) = from_server.next().await {
            if !(m.is_binary() || m.is_text()) {
                continue;
            }
            let pushed = lock().push(m);
            match pushed {
                Pushed::Queued => {}
                Pushed::DroppedOne => {
                    counts.dropped.fetch_add(1, Ordering::Relaxed);
                }
                Pushed::Full => {
                    counts.let_go.fetch_add(1, Ordering::Relaxed);
                    cut.notify_one();
                    return;
                }
            }
            ready.notify_one();
        }
        lock().ended = true;
        ready.notify_one();
    };
    // The outbox, sent to the client as fast as it reads.
    let send = async {
        loop {
            let next = {
                let mut o = lock();
                match o.pop() {
                    Some(m) => Some(m),
                    None if o.ended => break,
                    None => None,
                }
            };
            match next {
                Some(m) => {
                    if to_client.send(m).await.is_err() {
                        return;
                    }
                }
                None => ready.notified().await,
            }
        }
        let _ = to_client.close().await;
    };
    // The client's messages (subscriptions), passed on as they come.
    let up = async {
        while let Some(Ok(m)) = from_client.next().await {
            if m.is_close() {
                break;
            }
            if m.is_binary() || m.is_text() {
                spoke.store(true, Ordering::Relaxed);
                if to_server.send(m).await.is_err() {
                    break;
                }
            }
        }
        let _ = to_server.close().await;
    };
    tokio::select! {
        () = cut.notified() => {}
        () = up => {}
        ((), ()) = async { tokio::join!(down, send) } => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_name_of_the_protocol_is_answered_and_the_sdk_asked_for_its_own() {
        assert_eq!(
            choose(["foxglove.websocket.v1"]),
            Some(("foxglove.websocket.v1", "foxglove.sdk.v1"))
        );
        assert_eq!(
            choose(["foxglove.websocket.v1, foxglove.sdk.v1"]),
            Some(("foxglove.sdk.v1", "foxglove.sdk.v1"))
        );
        assert_eq!(
            choose(["foxglove.sdk.v1", "foxglove.sdk.v1.1"]),
            Some(("foxglove.sdk.v1.1", "foxglove.sdk.v1.1"))
        );
        // A whole name only: a prefix or a longer name is not the protocol.
        assert_eq!(choose(["foxglove.sdk", "foxglove.websocket.v10"]), None);
        assert_eq!(choose([]), None);
    }

    #[test]
    fn a_full_outbox_drops_its_oldest_binary_message_and_lets_go_a_client_of_text_only() {
        let mut o = Outbox::default();
        o.push(Message::text("serverInfo"));
        for i in 0..OUTBOX - 1 {
            assert_eq!(o.push(Message::binary(vec![1, i as u8])), Pushed::Queued);
        }
        assert_eq!(o.len(), OUTBOX);
        // Full: the oldest binary goes, the text before it stays.
        assert_eq!(o.push(Message::text("advertise")), Pushed::DroppedOne);
        assert_eq!(o.len(), OUTBOX);
        assert_eq!(o.pop(), Some(Message::text("serverInfo")));
        assert_eq!(o.pop(), Some(Message::binary(vec![1, 1])));
        // Full of text: a binary message is dropped itself, a text message lets the client go.
        let mut o = Outbox::default();
        for _ in 0..OUTBOX {
            o.push(Message::text("status"));
        }
        assert_eq!(o.push(Message::binary(vec![2])), Pushed::DroppedOne);
        assert_eq!(o.push(Message::text("status")), Pushed::Full);
        assert!(o.queue.iter().all(Message::is_text));
    }

    /// A stand-in for the SDK's server on loopback: records the subprotocol it was asked for,
    /// then sends `texts` text messages of 4 KiB as fast as the relay reads them.
    async fn upstream(texts: usize) -> (SocketAddr, tokio::sync::oneshot::Receiver<String>) {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("address");
        let (asked_tx, asked) = tokio::sync::oneshot::channel();
        tokio::spawn(async move {
            let (tcp, _) = listener.accept().await.expect("accept");
            let mut name = String::new();
            #[allow(clippy::result_large_err)]
            let note = |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
                if let Some(v) = req.headers().get(header::SEC_WEBSOCKET_PROTOCOL) {
                    name = v.to_str().unwrap_or("?").to_string();
                    resp.headers_mut()
                        .insert(header::SEC_WEBSOCKET_PROTOCOL, v.clone());
                }
                Ok(resp)
            };
            let mut ws = tokio_tungstenite::accept_hdr_async(tcp, note)
                .await
                .expect("handshake");
            let _ = asked_tx.send(name);
            let text = "x".repeat(4096);
            for _ in 0..texts {
                if ws.send(Message::text(text.clone())).await.is_err() {
                    return;
                }
            }
        });
        (addr, asked)
    }

    /// A stand-in for the SDK's server that takes any number of connections and sends each a
    /// binary message every 10 ms.
    async fn upstream_streaming() -> SocketAddr {
        let listener = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let addr = listener.local_addr().expect("address");
        tokio::spawn(async move {
            while let Ok((tcp, _)) = listener.accept().await {
                tokio::spawn(async move {
                    #[allow(clippy::result_large_err)]
                    let echo =
                        |req: &Request, mut resp: Response| -> Result<Response, ErrorResponse> {
                            if let Some(v) = req.headers().get(header::SEC_WEBSOCKET_PROTOCOL) {
                                resp.headers_mut()
                                    .insert(header::SEC_WEBSOCKET_PROTOCOL, v.clone());
                            }
                            Ok(resp)
                        };
                    let Ok(mut ws) = tokio_tungstenite::accept_hdr_async(tcp, echo).await else {
                        return;
                    };
                    while ws.send(Message::binary(vec![7u8; 16])).await.is_ok() {
                        tokio::time::sleep(Duration::from_millis(10)).await;
                    }
                });
            }
        });
        addr
    }

    /// A client of the door at `at` that finished its handshake.
    async fn connected(at: SocketAddr) -> tokio_tungstenite::WebSocketStream<TcpStream> {
        connected_as(at, "foxglove.sdk.v1").await.0
    }

    /// A client of the door at `at` offering `protocol`, its handshake done, and the answer.
    async fn connected_as(
        at: SocketAddr,
        protocol: &'static str,
    ) -> (
        tokio_tungstenite::WebSocketStream<TcpStream>,
        tokio_tungstenite::tungstenite::handshake::client::Response,
    ) {
        let mut request = format!("ws://{at}/")
            .into_client_request()
            .expect("request");
        request.headers_mut().insert(
            header::SEC_WEBSOCKET_PROTOCOL,
            HeaderValue::from_static(protocol),
        );
        let tcp = TcpStream::connect(at).await.expect("connect");
        tokio_tungstenite::client_async(request, tcp)
            .await
            .expect("the door answers")
    }

    /// Regression (issue 51): 64 clients that finished their handshake and then said nothing
    /// held every place of the door, and a viewer was refused for the whole run. With 100 such
    /// clients held open, a viewer that connects and subscribes (any message) gets a place
    /// (the oldest silent connection's) and receives the server's messages; a client that has
    /// spoken is never evicted for a new one.
    #[tokio::test(flavor = "multi_thread", worker_threads = 1)]
    async fn idle_connections_however_many_never_keep_a_viewer_out() {
        let up = upstream_streaming().await;
        let door = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let at = door.local_addr().expect("address");
        let counts = Arc::new(Counts::default());
        tokio::spawn(serve(door, up, counts.clone()));
        let mut idle = Vec::new();
        for _ in 0..100 {
            idle.push(connected(at).await);
        }
        let mut viewer = connected(at).await;
        viewer
            .send(Message::text(r#"{"op":"subscribe","subscriptions":[]}"#))
            .await
            .expect("subscribed");
        let received = tokio::time::timeout(Duration::from_secs(30), async {
            while let Some(Ok(m)) = viewer.next().await {
                if m.is_binary() {
                    return true;
                }
            }
            false
        })
        .await;
        assert_eq!(received, Ok(true), "the viewer received the server's data");
        assert!(
            counts.let_go.load(Ordering::Relaxed) >= 37,
            "silent ones made room"
        );
        assert!(counts.open.load(Ordering::Relaxed) <= MAX_CONNECTIONS as u64);
        // The viewer has spoken: 64 more silent clients take the others' places, not its own.
        for _ in 0..64 {
            idle.push(connected(at).await);
        }
        let still = tokio::time::timeout(Duration::from_secs(30), async {
            let mut binaries = 0;
            while let Some(Ok(m)) = viewer.next().await {
                binaries += usize::from(m.is_binary());
                if binaries >= 10 {
                    return true;
                }
            }
            false
        })
        .await;
        assert_eq!(still, Ok(true), "the viewer kept its place");
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 1)]
    async fn a_client_of_the_old_name_is_relayed_under_the_new_and_let_go_when_it_never_reads() {
        // 16 000 control messages of 4 KiB (64 MiB): more than its sockets and its outbox hold.
        let (up, asked) = upstream(16_000).await;
        let door = TcpListener::bind("127.0.0.1:0").await.expect("bind");
        let at = door.local_addr().expect("address");
        let counts = Arc::new(Counts::default());
        tokio::spawn(serve(door, up, counts.clone()));
        let (client, answer) = connected_as(at, "foxglove.websocket.v1").await;
        assert_eq!(
            answer.headers().get(header::SEC_WEBSOCKET_PROTOCOL),
            Some(&HeaderValue::from_static("foxglove.websocket.v1"))
        );
        assert_eq!(asked.await.expect("asked"), "foxglove.sdk.v1");
        // The client reads nothing: once its outbox is full of control messages it is let go,
        // and its connection closed.
        let end = tokio::time::Instant::now() + Duration::from_secs(30);
        while counts.open.load(Ordering::Relaxed) > 0 && tokio::time::Instant::now() < end {
            tokio::time::sleep(Duration::from_millis(20)).await;
        }
        assert_eq!(counts.let_go.load(Ordering::Relaxed), 1);
        assert_eq!(counts.open.load(Ordering::Relaxed), 0, "still open");
        drop(client);
    }
}
