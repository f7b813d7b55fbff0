//! The web server of the web expert: an axum application on its own tokio runtime thread.
//!
//! It serves only the embedded page (`/`, `/app.js`, `/style.css`) and one WebSocket (`/ws`), all behind the
//! access token (`?token=...`, exactly once, 403 otherwise) and behind a `Host` and `Origin` that name the served
//! address (so that the page of another site cannot reach the server by DNS rebinding). The training thread and the server share a [`Board`]: the latest
//! status, frame and prompt and the history, so that a tab that connects (or reloads) late sees everything at
//! once; every change is also broadcast to the open tabs. One tab controls (the first one, or the one that took
//! control); its keys go to the training thread over a channel, the others watch.
//!
//! A crowd of idle or slow connections cannot lock the person out ([`Gate`]): at most [`MAX_CONNECTIONS`] are
//! open at once, at most [`MAX_PER_ADDRESS`] from one address; a connection that is not an open tab must finish
//! each request within [`REQUEST_DEADLINE`] of its opening or of the server's last response, and when the server
//! is full, a new connection takes the place of the oldest one that is not an open tab.

use super::protocol::{ActionCheck, ClientMsg, ServerMsg};
use axum::Router;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{ConnectInfo, Request, State};
use axum::http::{StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::get;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, mpsc};
use tokio::sync::{broadcast, oneshot};

const INDEX_HTML: &str = include_str!("page/index.html");
const APP_JS: &str = include_str!("page/app.js");
const STYLE_CSS: &str = include_str!("page/style.css");

/// The page's Content-Security-Policy: its own script, style and WebSocket only; images from `data:` (the
/// rendered frames).
const CSP: &str = "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self' data:; \
                   connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'";

/// Uncertainty samples kept for the live chart.
pub const UNCERTAINTY_HISTORY: usize = 300;
/// The longest message a page may send (bytes); its messages are a few dozen bytes.
const MAX_CLIENT_MESSAGE: usize = 1024;

/// What the controlling tab answered to prompt `id`.
#[derive(Clone, Debug, PartialEq)]
pub struct KeyInput {
    pub id: u64,
    pub input: Input,
}

/// An answer of the person.
#[derive(Clone, Debug, PartialEq)]
pub enum Input {
    /// An action as the page sent it (checked: an index, or a box's numbers), and whether the gesture that gave
    /// it was the action itself ([`ClientMsg::Key`]'s `acting`).
    Action {
        action: serde_json::Value,
        acting: bool,
    },
    /// The question goes back to the agent.
    HandBack,
    /// Take back the last key.
    Undo,
    /// Play the last segment again from its start state.
    Retry,
}

/// What the training thread last published, for tabs that connect later.
#[derive(Default)]
pub struct Board {
    /// The run's `hello` message and the check of its actions, once the run has started.
    pub hello: Option<String>,
    pub check: Option<ActionCheck>,
    pub status: Option<String>,
    pub frame: Option<String>,
    pub prompt: Option<String>,
    pub uncertainty: Vec<(usize, f32, Option<f32>)>,
    pub curve: Vec<(u64, f64)>,
    pub end: Option<String>,
    /// The note shown while the run is handed to its program (a Python `learn` returned), until it goes on.
    pub handed: Option<String>,
    /// Open tabs, oldest first.
    clients: Vec<u64>,
    controller: Option<u64>,
    /// The action held down in the controlling tab (real time).
    pub held: Option<serde_json::Value>,
    /// Whether the controlling tab paused the run.
    pub paused: bool,
    /// Real time: whether a takeover can be asked for now, and whether one is asked for ([`Takeover`]).
    pub takeover: Takeover,
    /// Real time: whether the controlling tab watches the agent's own steps at the real-time rate.
    pub watch: bool,
    /// The person's absence (the run paused, or no tab open): the time absent before `absent_since`, and since
    /// when they are absent now. Such time is not charged to the person.
    absent_before: std::time::Duration,
    absent_since: Option<std::time::Instant>,
}

impl Board {
    /// The messages that bring tab `client` up to date.
    fn snapshot(&self, client: u64) -> Vec<String> {
        let mut msgs = vec![ServerMsg::Welcome { client }.to_json()];
        msgs.extend(self.hello.clone());
        msgs.extend([
            ServerMsg::Roles {
                controller: self.controller,
            }
            .to_json(),
            ServerMsg::History {
                uncertainty: &self.uncertainty,
                curve: &self.curve,
            }
            .to_json(),
        ]);
        msgs.extend(
            [
                &self.status,
                &self.frame,
                &self.prompt,
                &self.handed,
                &self.end,
            ]
            .into_iter()
            .flatten()
            .cloned(),
        );
        if self.prompt.is_none() {
            msgs.push(ServerMsg::Prompt { prompt: None }.to_json());
        }
        msgs.push(
            ServerMsg::Paused {
                paused: self.paused,
            }
            .to_json(),
        );
        msgs.push(self.takeover.to_json());
        msgs.push(ServerMsg::Watch { on: self.watch }.to_json());
        msgs
    }

    fn roles(&self) -> String {
        ServerMsg::Roles {
            controller: self.controller,
        }
        .to_json()
    }

    pub fn open_tabs(&self) -> usize {
        self.clients.len()
    }

    /// Notes a change of the person's presence (a pause, a tab opened or closed) at `now`.
    fn presence_changed(&mut self, now: std::time::Instant) {
        let absent = self.paused || self.clients.is_empty();
        match (absent, self.absent_since) {
            (true, None) => self.absent_since = Some(now),
            (false, Some(since)) => {
                self.absent_before += now.saturating_duration_since(since);
                self.absent_since = None;
            }
            _ => {}
        }
    }

    /// The time the person was absent (paused, or no tab open) until `now`, since the board was made.
    pub fn absent(&self, now: std::time::Instant) -> std::time::Duration {
        self.absent_before
            + self
                .absent_since
                .map_or(std::time::Duration::ZERO, |since| {
                    now.saturating_duration_since(since)
                })
    }
}

/// Real time: the person's request to take over, and whether the run can take one now. The training thread
/// offers a takeover only while the agent acts (not while a question is open or coming: the breath before a
/// question, its replay, its segment); the page asks for it, or cancels its request, and the run takes a request
/// at its next step. A request can only be made while a takeover is offered, and ends when the offer does (a
/// question then opens instead), so that a takeover never starts from a key pressed before the agent acted.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Takeover {
    /// The agent acts: a request now is taken at its next step.
    pub offered: bool,
    /// The controlling tab asked to take over, and the run has not taken it yet.
    pub pending: bool,
}

impl Takeover {
    fn to_json(self) -> String {
        ServerMsg::Takeover {
            offered: self.offered,
            pending: self.pending,
        }
        .to_json()
    }
}

/// State shared by the training thread and the server.
pub struct Shared {
    token: String,
    /// The address served (`Host` and `Origin` must name it).
    served: std::net::SocketAddr,
    pub board: Mutex<Board>,
    updates: broadcast::Sender<Arc<str>>,
    keys: Mutex<mpsc::Sender<KeyInput>>,
    next_client: AtomicU64,
}

impl Shared {
    pub fn new(token: String, served: std::net::SocketAddr, keys: mpsc::Sender<KeyInput>) -> Self {
        Self {
            token,
            served,
            // No tab is open yet: the person is absent from the start.
            board: Mutex::new(Board {
                absent_since: Some(std::time::Instant::now()),
                ..Board::default()
            }),
            updates: broadcast::channel(256).0,
            keys: Mutex::new(keys),
            next_client: AtomicU64::new(1),
        }
    }

    fn board(&self) -> std::sync::MutexGuard<'_, Board> {
        // A panic while holding the lock leaves plain data behind; keep serving it.
        self.board.lock().unwrap_or_else(|e| e.into_inner())
    }

    /// Changes the board and broadcasts `msg` under one lock, so a tab never misses or reorders an update.
    pub fn publish(&self, msg: String, update: impl FnOnce(&mut Board, &String)) {
        let mut board = self.board();
        update(&mut board, &msg);
        let _ = self.updates.send(Arc::from(msg));
    }

    /// Adds an uncertainty sample to the history (no broadcast: the status message carries it).
    pub fn push_uncertainty(&self, sample: (usize, f32, Option<f32>)) {
        let mut board = self.board();
        if board.uncertainty.len() >= UNCERTAINTY_HISTORY {
            board.uncertainty.remove(0);
        }
        board.uncertainty.push(sample);
    }

    /// Changes the takeover's state under the board's lock, telling the tabs when it changed; returns the
    /// state before.
    fn update_takeover(&self, change: impl FnOnce(&mut Takeover)) -> Takeover {
        let mut board = self.board();
        let before = board.takeover;
        change(&mut board.takeover);
        if board.takeover != before {
            let _ = self.updates.send(Arc::from(board.takeover.to_json()));
        }
        before
    }

    /// Whether the controlling tab asked to take over and the run has not taken it yet: the request is taken
    /// (the takeover's segment opens, so nothing more is offered until the agent acts again).
    pub fn take_takeover(&self) -> bool {
        let before = self.update_takeover(|t| {
            if t.pending {
                *t = Takeover::default();
            }
        });
        before.pending
    }

    /// Offers a takeover (the agent acts) or withdraws the offer (a question opens, or is about to); a request
    /// still pending when the offer ends is dropped. Returns whether one was pending.
    pub fn offer_takeover(&self, offered: bool) -> bool {
        let before = self.update_takeover(|t| {
            t.offered = offered;
            t.pending &= offered;
        });
        before.pending && !offered
    }

    /// The page asks to take over (`cancel`: withdraws its request); refused when no takeover is offered.
    fn request_takeover(&self, board: &mut Board, cancel: bool) -> Result<(), String> {
        let before = board.takeover;
        if cancel {
            board.takeover.pending = false;
        } else if board.takeover.offered {
            board.takeover.pending = true;
        } else {
            return Err(
                "no takeover now: take over while the agent acts (its question comes first)".into(),
            );
        }
        if board.takeover != before {
            let _ = self.updates.send(Arc::from(board.takeover.to_json()));
        }
        Ok(())
    }

    pub fn held(&self) -> Option<serde_json::Value> {
        self.board().held.clone()
    }

    pub fn paused(&self) -> bool {
        self.board().paused
    }

    /// Whether the agent's own steps go at the real-time rate (watch mode).
    pub fn watching(&self) -> bool {
        self.board().watch
    }

    /// The time the person was absent until `now` (paused, or no tab open): subtracted from the person's time.
    pub fn absent_at(&self, now: std::time::Instant) -> std::time::Duration {
        self.board().absent(now)
    }

    /// The time from `start` until now that the person was present (the run not paused, a tab open), given
    /// `absent_at_start`, what [`Self::absent_at`] said at `start`.
    pub fn present_since(
        &self,
        start: std::time::Instant,
        absent_at_start: std::time::Duration,
    ) -> std::time::Duration {
        let now = std::time::Instant::now();
        let absent = self.absent_at(now).saturating_sub(absent_at_start);
        (now - start).saturating_sub(absent)
    }

    /// Whether the end of the run was published.
    pub fn ended(&self) -> bool {
        self.board().end.is_some()
    }

    pub fn open_tabs(&self) -> usize {
        self.board().open_tabs()
    }

    /// Whether the query string holds the token, exactly once.
    fn token_ok(&self, query: Option<&str>) -> bool {
        let mut tokens = query
            .unwrap_or_default()
            .split('&')
            .filter_map(|kv| kv.strip_prefix("token="));
        match (tokens.next(), tokens.next()) {
            (Some(t), None) => constant_time_eq(t.as_bytes(), self.token.as_bytes()),
            _ => false,
        }
    }

    /// Whether `host` (a `Host` header, or an `Origin` without its scheme) names the served address: an IP
    /// literal of it (any of this machine's when it serves every interface) or `localhost`, with its port. A
    /// name that some DNS resolves to this machine is refused: the page of another site could otherwise reach
    /// the server by DNS rebinding.
    fn host_ok(&self, host: &str) -> bool {
        let Some((name, port)) = host.rsplit_once(':') else {
            return false;
        };
        if port.parse::<u16>() != Ok(self.served.port()) {
            return false;
        }
        let ip = name
            .trim_start_matches('[')
            .trim_end_matches(']')
            .parse::<std::net::IpAddr>();
        match ip {
            Ok(ip) if self.served.ip().is_unspecified() => {
                !ip.is_unspecified() && !ip.is_multicast()
            }
            Ok(ip) => {
                ip == self.served.ip() || (ip.is_loopback() && self.served.ip().is_loopback())
            }
            Err(_) => {
                name.eq_ignore_ascii_case("localhost") && self.served.ip().is_loopback()
                    || name.eq_ignore_ascii_case("localhost") && self.served.ip().is_unspecified()
            }
        }
    }

    /// Whether a request's `Host` and `Origin` (when it has one) name the served address, and agree.
    fn origin_ok(&self, headers: &axum::http::HeaderMap) -> bool {
        let host = headers.get(header::HOST).and_then(|h| h.to_str().ok());
        let Some(host) = host.filter(|h| self.host_ok(h)) else {
            return false;
        };
        match headers.get(header::ORIGIN) {
            None => true,
            Some(origin) => origin
                .to_str()
                .ok()
                .and_then(|o| o.strip_prefix("http://"))
                .is_some_and(|o| o.eq_ignore_ascii_case(host)),
        }
    }
}

/// Compares without stopping at the first difference (the time taken does not reveal the token's prefix).
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

/// Serves on `listener` until `stop` fires, on a runtime thread of its own.
pub fn spawn(
    listener: std::net::TcpListener,
    shared: Arc<Shared>,
    stop: oneshot::Receiver<()>,
) -> anyhow::Result<std::thread::JoinHandle<()>> {
    listener.set_nonblocking(true)?;
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()?;
    let handle = std::thread::Builder::new()
        .name("arld-web".into())
        .spawn(move || {
            runtime.block_on(async move {
                let listener = match tokio::net::TcpListener::from_std(listener) {
                    Ok(l) => l,
                    Err(err) => {
                        eprintln!("error: the web expert's server cannot start: {err}");
                        return;
                    }
                };
                let listener = Bounded {
                    inner: listener,
                    gate: Arc::new(Gate::default()),
                };
                let app = router(shared).into_make_service_with_connect_info::<Connection>();
                tokio::select! {
                    result = axum::serve(listener, app) => {
                        if let Err(err) = result {
                            eprintln!("error: the web expert's server stopped: {err}");
                        }
                    }
                    _ = stop => {}
                }
            });
            // Dropping the runtime here ends every connection still open.
        })?;
    Ok(handle)
}

/// The most connections the server holds open at once (idle connections cannot use up the process's open
/// files, which the run needs too).
pub const MAX_CONNECTIONS: usize = 32;
/// The most connections open at once from one address.
pub const MAX_PER_ADDRESS: usize = 16;
/// How long a connection that is not an open tab may take to send a whole request, from its opening or from the
/// server's last response on it (a page loads its three files at once).
pub const REQUEST_DEADLINE: std::time::Duration = std::time::Duration::from_secs(10);

/// The connections open: which may stay and which must make room ([`Gate::admit`]).
#[derive(Default)]
struct Gate {
    /// Oldest first.
    open: Mutex<Vec<Arc<Conn>>>,
}

/// One open connection, as the gate sees it.
struct Conn {
    ip: std::net::IpAddr,
    /// Whether it became an open tab (a WebSocket that passed the token): it stays as long as the tab does.
    tab: AtomicBool,
    /// Whether the gate closed it (to make room); its next read ends it.
    closed: AtomicBool,
    /// The task reading from it, woken when the gate closes it.
    reader: Mutex<Option<std::task::Waker>>,
}

impl Conn {
    fn close(&self) {
        self.closed.store(true, Ordering::Relaxed);
        if let Some(waker) = self.reader.lock().unwrap_or_else(|e| e.into_inner()).take() {
            waker.wake();
        }
    }
}

impl Gate {
    /// Admits a connection from `ip`, closing the oldest connection that is not a tab (from `ip` when that
    /// address has its most) if the server is full; `None` (the connection is refused) when every connection in
    /// the way is an open tab.
    fn admit(&self, ip: std::net::IpAddr) -> Option<Arc<Conn>> {
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        open.retain(|c| !c.closed.load(Ordering::Relaxed));
        for (limit, same) in [
            (
                MAX_PER_ADDRESS,
                &(|c: &Conn| c.ip == ip) as &dyn Fn(&Conn) -> bool,
            ),
            (MAX_CONNECTIONS, &|_: &Conn| true),
        ] {
            if open.iter().filter(|c| same(c)).count() >= limit {
                let oldest = open
                    .iter()
                    .position(|c| same(c) && !c.tab.load(Ordering::Relaxed))?;
                open.remove(oldest).close();
            }
        }
        let conn = Arc::new(Conn {
            ip,
            tab: AtomicBool::new(false),
            closed: AtomicBool::new(false),
            reader: Mutex::new(None),
        });
        open.push(Arc::clone(&conn));
        Some(conn)
    }

    fn leave(&self, conn: &Arc<Conn>) {
        let mut open = self.open.lock().unwrap_or_else(|e| e.into_inner());
        open.retain(|c| !Arc::ptr_eq(c, conn));
    }
}

/// The listener: every connection accepted goes through the [`Gate`].
struct Bounded {
    inner: tokio::net::TcpListener,
    gate: Arc<Gate>,
}

/// A connection with its place at the gate and its request deadline.
struct Counted {
    io: tokio::net::TcpStream,
    conn: Arc<Conn>,
    gate: Arc<Gate>,
    deadline: std::pin::Pin<Box<tokio::time::Sleep>>,
}

impl Drop for Counted {
    fn drop(&mut self) {
        self.gate.leave(&self.conn);
    }
}

impl axum::serve::Listener for Bounded {
    type Io = Counted;
    type Addr = std::net::SocketAddr;

    async fn accept(&mut self) -> (Self::Io, Self::Addr) {
        loop {
            let (tcp, addr) = match self.inner.accept().await {
                Ok(accepted) => accepted,
                // Out of open files, or a connection reset before it was accepted: try again shortly.
                Err(_) => {
                    tokio::time::sleep(std::time::Duration::from_millis(50)).await;
                    continue;
                }
            };
            let Some(conn) = self.gate.admit(addr.ip()) else {
                continue;
            };
            // Small messages leave at once: Nagle's algorithm with delayed acknowledgements would hold each
            // step's update for tens of milliseconds.
            let _ = tcp.set_nodelay(true);
            let counted = Counted {
                io: tcp,
                conn,
                gate: Arc::clone(&self.gate),
                deadline: Box::pin(tokio::time::sleep(REQUEST_DEADLINE)),
            };
            return (counted, addr);
        }
    }

    fn local_addr(&self) -> std::io::Result<Self::Addr> {
        self.inner.local_addr()
    }
}

/// What a handler knows of its connection: the tab handler marks it as a tab.
#[derive(Clone)]
struct Connection(Arc<Conn>);

impl axum::extract::connect_info::Connected<axum::serve::IncomingStream<'_, Bounded>>
    for Connection
{
    fn connect_info(stream: axum::serve::IncomingStream<'_, Bounded>) -> Self {
        Connection(Arc::clone(&stream.io().conn))
    }
}

impl tokio::io::AsyncRead for Counted {
    fn poll_read(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &mut tokio::io::ReadBuf<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        use std::task::Poll;
        let ended = |why: &str| {
            Poll::Ready(Err(std::io::Error::new(
                std::io::ErrorKind::TimedOut,
                why.to_string(),
            )))
        };
        *self.conn.reader.lock().unwrap_or_else(|e| e.into_inner()) = Some(cx.waker().clone());
        if self.conn.closed.load(Ordering::Relaxed) {
            return ended("closed to make room for another connection");
        }
        if !self.conn.tab.load(Ordering::Relaxed) && self.deadline.as_mut().poll(cx).is_ready() {
            self.conn.close();
            return ended("no whole request within the deadline");
        }
        std::pin::Pin::new(&mut self.io).poll_read(cx, buf)
    }
}

impl tokio::io::AsyncWrite for Counted {
    fn poll_write(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
        buf: &[u8],
    ) -> std::task::Poll<std::io::Result<usize>> {
        let written = std::pin::Pin::new(&mut self.io).poll_write(cx, buf);
        if matches!(written, std::task::Poll::Ready(Ok(n)) if n > 0) {
            // A response went out: the client has the deadline again for its next request.
            let next = tokio::time::Instant::now() + REQUEST_DEADLINE;
            self.deadline.as_mut().reset(next);
        }
        written
    }

    fn poll_flush(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.io).poll_flush(cx)
    }

    fn poll_shutdown(
        mut self: std::pin::Pin<&mut Self>,
        cx: &mut std::task::Context<'_>,
    ) -> std::task::Poll<std::io::Result<()>> {
        std::pin::Pin::new(&mut self.io).poll_shutdown(cx)
    }
}

fn router(shared: Arc<Shared>) -> Router {
    Router::new()
        .route("/", get(index))
        .route(
            "/app.js",
            get(|| async { asset("text/javascript", APP_JS) }),
        )
        .route("/style.css", get(|| async { asset("text/css", STYLE_CSS) }))
        .route("/ws", get(websocket))
        .fallback(|| async { (StatusCode::NOT_FOUND, "not found\n") })
        .layer(middleware::from_fn_with_state(
            shared.clone(),
            require_token,
        ))
        .with_state(shared)
}

/// Every request, whatever its path, needs the token (once), and a `Host` and `Origin` naming the served address.
async fn require_token(State(shared): State<Arc<Shared>>, req: Request, next: Next) -> Response {
    if !shared.origin_ok(req.headers()) {
        return (
            StatusCode::FORBIDDEN,
            "forbidden: open the URL that arld printed (this request names another host or origin)\n",
        )
            .into_response();
    }
    if !shared.token_ok(req.uri().query()) {
        return (
            StatusCode::FORBIDDEN,
            "forbidden: open the URL with the token that arld printed\n",
        )
            .into_response();
    }
    next.run(req).await
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [
            (header::CONTENT_TYPE, content_type),
            (header::CACHE_CONTROL, "no-store"),
            (header::X_CONTENT_TYPE_OPTIONS, "nosniff"),
        ],
        body,
    )
        .into_response()
}

async fn index(State(shared): State<Arc<Shared>>) -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-store"),
            (header::X_FRAME_OPTIONS, "DENY"),
            (header::REFERRER_POLICY, "no-referrer"),
            (header::CONTENT_SECURITY_POLICY, CSP),
        ],
        INDEX_HTML.replace("__TOKEN__", &shared.token),
    )
        .into_response()
}

async fn websocket(
    State(shared): State<Arc<Shared>>,
    ConnectInfo(connection): ConnectInfo<Connection>,
    ws: WebSocketUpgrade,
) -> Response {
    // Past the token: an open tab, which no deadline or newcomer closes.
    connection.0.tab.store(true, Ordering::Relaxed);
    ws.max_message_size(MAX_CLIENT_MESSAGE)
        .on_upgrade(move |socket| tab(socket, shared))
}

/// One open tab: catch it up, then forward updates to it and its keys to the training thread.
async fn tab(mut socket: WebSocket, shared: Arc<Shared>) {
    let id = shared.next_client.fetch_add(1, Ordering::Relaxed);
    let (mut updates, snapshot) = {
        let mut board = shared.board();
        board.clients.push(id);
        board.presence_changed(std::time::Instant::now());
        if board.controller.is_none() {
            board.controller = Some(id);
            let _ = shared.updates.send(Arc::from(board.roles()));
        }
        (shared.updates.subscribe(), board.snapshot(id))
    };
    let mut open = true;
    for msg in snapshot {
        if socket.send(Message::Text(msg.into())).await.is_err() {
            open = false;
            break;
        }
    }
    while open {
        tokio::select! {
            update = updates.recv() => match update {
                Ok(msg) => {
                    let end = msg.starts_with(r#"{"type":"end""#);
                    open = socket.send(Message::Text(msg.as_ref().into())).await.is_ok() && !end;
                }
                // The tab fell behind: send it the whole picture again.
                Err(broadcast::error::RecvError::Lagged(_)) => {
                    let snapshot = shared.board().snapshot(id);
                    for msg in snapshot {
                        if socket.send(Message::Text(msg.into())).await.is_err() {
                            open = false;
                            break;
                        }
                    }
                }
                Err(broadcast::error::RecvError::Closed) => open = false,
            },
            incoming = socket.recv() => match incoming {
                Some(Ok(Message::Text(text))) => {
                    if let Err(message) = handle(&shared, id, text.as_str()) {
                        let frame = ServerMsg::Error { message }.to_json();
                        open = socket.send(Message::Text(frame.into())).await.is_ok();
                    }
                }
                Some(Ok(Message::Binary(_))) => {
                    let message = "binary messages are not understood; send JSON text".to_string();
                    let frame = ServerMsg::Error { message }.to_json();
                    open = socket.send(Message::Text(frame.into())).await.is_ok();
                }
                Some(Ok(Message::Ping(_) | Message::Pong(_))) => {}
                Some(Ok(Message::Close(_)) | Err(_)) | None => open = false,
            },
        }
    }
    let _ = socket.send(Message::Close(None)).await;
    let mut board = shared.board();
    board.clients.retain(|&c| c != id);
    board.presence_changed(std::time::Instant::now());
    if board.controller == Some(id) {
        board.controller = board.clients.first().copied();
        board.held = None;
        // A pause stays when its tab closes: the next tab to control the run lifts it (a new tab controls
        // when no other is open).
        let _ = shared.updates.send(Arc::from(board.roles()));
    }
}

/// Applies one message of tab `id`; an error is the message of the error frame sent back.
fn handle(shared: &Shared, id: u64, text: &str) -> Result<(), String> {
    let mut board = shared.board();
    // Before the run has started there is no action to give.
    let check = board
        .check
        .clone()
        .unwrap_or_else(|| super::protocol::discrete_check(0));
    let msg = ClientMsg::parse(text, &check)?;
    let controls = board.controller == Some(id);
    match msg {
        ClientMsg::Control => {
            if !controls {
                board.controller = Some(id);
                board.held = None;
                let _ = shared.updates.send(Arc::from(board.roles()));
            }
            Ok(())
        }
        _ if !controls => {
            Err("this tab is watching: another tab controls the run (take control first)".into())
        }
        ClientMsg::Hold { action } => {
            board.held = action;
            Ok(())
        }
        ClientMsg::Pause { paused } => {
            board.paused = paused;
            board.presence_changed(std::time::Instant::now());
            let _ = shared
                .updates
                .send(Arc::from(ServerMsg::Paused { paused }.to_json()));
            Ok(())
        }
        ClientMsg::Watch { on } => {
            board.watch = on;
            let _ = shared
                .updates
                .send(Arc::from(ServerMsg::Watch { on }.to_json()));
            Ok(())
        }
        ClientMsg::Key { id, action, acting } => {
            send_key(shared, board, id, Input::Action { action, acting })
        }
        ClientMsg::Pass { id } => send_key(shared, board, id, Input::HandBack),
        ClientMsg::Takeover { cancel } => shared.request_takeover(&mut board, cancel),
        ClientMsg::Undo { id } => send_key(shared, board, id, Input::Undo),
        ClientMsg::Retry { id } => send_key(shared, board, id, Input::Retry),
    }
}

fn send_key(
    shared: &Shared,
    board: std::sync::MutexGuard<'_, Board>,
    id: u64,
    input: Input,
) -> Result<(), String> {
    drop(board);
    shared
        .keys
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .send(KeyInput { id, input })
        .map_err(|_| "the run is over".to_string())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A takeover is asked for only while one is offered (the agent acts); a request can be cancelled; the run
    /// takes it once; an offer withdrawn (a question opens) drops the request; every change reaches the tabs.
    #[test]
    fn a_takeover_is_asked_for_while_offered_cancelled_or_taken_once() {
        let (keys, _rx) = mpsc::channel();
        let shared = Shared::new("t".into(), "127.0.0.1:1".parse().unwrap(), keys);
        let mut tab = shared.updates.subscribe();
        let ask = |cancel: bool| shared.request_takeover(&mut shared.board(), cancel);
        let err = ask(false).unwrap_err();
        assert!(err.contains("while the agent acts"), "{err}");
        assert!(!shared.take_takeover());
        assert!(!shared.offer_takeover(true));
        ask(false).unwrap();
        ask(true).unwrap();
        assert!(!shared.take_takeover(), "a cancelled request was taken");
        ask(false).unwrap();
        assert!(shared.take_takeover());
        assert!(!shared.take_takeover(), "a request was taken twice");
        // Taken, the offer ends with it (the takeover's segment opens).
        assert!(ask(false).is_err());
        shared.offer_takeover(true);
        ask(false).unwrap();
        // A question opens: the request is dropped, not kept for after it.
        assert!(shared.offer_takeover(false));
        assert!(!shared.take_takeover());
        let mut seen = Vec::new();
        while let Ok(msg) = tab.try_recv() {
            let m: serde_json::Value = serde_json::from_str(&msg).unwrap();
            seen.push((
                m["offered"].as_bool().unwrap(),
                m["pending"].as_bool().unwrap(),
            ));
        }
        assert_eq!(
            seen,
            [
                (true, false),
                (true, true),
                (true, false),
                (true, true),
                (false, false),
                (true, false),
                (true, true),
                (false, false),
            ]
        );
    }
}
