//! The viewer's HTTP + WebSocket server on 127.0.0.1 (axum on a one-worker tokio runtime in its
//! own thread). Routes:
//!
//! - `GET /`, `/viewer.js`: the page and its WebGL viewer, embedded in the binary;
//! - `GET /mesh.bin`: the display surface (see [`super`]); `GET /api/info`: scene facts (JSON);
//! - `GET /ws`: WebSocket; the server sends binary frames, always the newest one (a tokio
//!   `watch` channel: a viewer that falls behind skips frames); the page sends JSON text:
//!   `{"aim": [x, y, z], "depth": d}` to steer the tool (virtual device only) and
//!   `{"report": {...}}` with what it rendered;
//! - `POST /api/steer`: the same steering message, for scripts and tests;
//! - `GET /api/status`: frames published, viewers connected, the newest frame's header and the
//!   newest viewer report (JSON).

use super::FrameInfo;
use anyhow::{Context, Result};
use axum::Router;
use axum::extract::State as AxState;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::http::{StatusCode, header};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde_json::{Value, json};
use std::net::SocketAddr;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use tokio::sync::watch;

const INDEX_HTML: &str = include_str!("assets/index.html");
const VIEWER_JS: &str = include_str!("assets/viewer.js");

/// Steers the tool at a surface point `aim` (m) with `depth` (m) along the shaft.
pub type SteerFn = Arc<dyn Fn([f64; 3], f64) + Send + Sync>;

#[derive(Default)]
struct Status {
    frames: u64,
    frame: Option<Value>,
    report: Option<Value>,
}

/// The publishing side, used by the frame loop: keeps only the newest frame.
#[derive(Clone)]
pub struct Hub {
    frames: watch::Sender<Arc<Vec<u8>>>,
    status: Arc<Mutex<Status>>,
}

impl Hub {
    /// Publishes a frame (never blocks on viewers).
    pub fn publish(&self, bytes: Vec<u8>, info: &FrameInfo) {
        self.frames.send_replace(Arc::new(bytes));
        if let Ok(mut s) = self.status.lock() {
            s.frames += 1;
            s.frame = Some(json!({
                "seq": info.seq, "tick": info.tick, "state": format!("{:?}", info.state),
                "contacts": info.contacts, "exact": info.exact, "tip_m": info.tip_m,
                "tool_force_n": info.tool_force_n, "tick_rate_hz": info.tick_rate_hz,
                "display_fps": info.display_fps,
            }));
        }
    }
}

#[derive(Clone)]
struct App {
    mesh: Arc<Vec<u8>>,
    info: Arc<Value>,
    frames: watch::Receiver<Arc<Vec<u8>>>,
    status: Arc<Mutex<Status>>,
    viewers: Arc<AtomicUsize>,
    steer: Option<SteerFn>,
}

/// A running server; it stops with the process.
pub struct Server {
    /// Where it listens.
    pub addr: SocketAddr,
    /// Its publishing side.
    pub hub: Hub,
}

impl Server {
    /// Binds `127.0.0.1:port` (0: any free port) and serves `mesh` (`/mesh.bin` bytes) and
    /// `info` (`/api/info`); `steer` receives steering messages.
    pub fn start(port: u16, mesh: Vec<u8>, info: Value, steer: Option<SteerFn>) -> Result<Server> {
        let listener = std::net::TcpListener::bind(("127.0.0.1", port))
            .with_context(|| format!("cannot listen on 127.0.0.1:{port}"))?;
        listener.set_nonblocking(true)?;
        let addr = listener.local_addr()?;
        let (tx, rx) = watch::channel(Arc::new(Vec::new()));
        let status = Arc::new(Mutex::new(Status::default()));
        let app = App {
            mesh: Arc::new(mesh),
            info: Arc::new(info),
            frames: rx,
            status: Arc::clone(&status),
            viewers: Arc::new(AtomicUsize::new(0)),
            steer,
        };
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("display-server")
            .enable_all()
            .build()?;
        std::thread::Builder::new()
            .name("display-server".into())
            .spawn(move || {
                runtime.block_on(async move {
                    let Ok(listener) = tokio::net::TcpListener::from_std(listener) else {
                        return;
                    };
                    let router = Router::new()
                        .route("/", get(index))
                        .route("/viewer.js", get(viewer_js))
                        .route("/mesh.bin", get(mesh_bin))
                        .route("/api/info", get(info_json))
                        .route("/api/status", get(status_json))
                        .route("/api/steer", post(steer_post))
                        .route("/ws", get(ws_upgrade))
                        .with_state(app);
                    let _ = axum::serve(listener, router).await;
                });
            })?;
        Ok(Server {
            addr,
            hub: Hub { frames: tx, status },
        })
    }
}

async fn index() -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, "text/html; charset=utf-8")],
        INDEX_HTML,
    )
}

async fn viewer_js() -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, "text/javascript; charset=utf-8")],
        VIEWER_JS,
    )
}

async fn mesh_bin(AxState(app): AxState<App>) -> impl IntoResponse {
    (
        [(header::CONTENT_TYPE, "application/octet-stream")],
        app.mesh.as_ref().clone(),
    )
}

async fn info_json(AxState(app): AxState<App>) -> impl IntoResponse {
    axum::Json(app.info.as_ref().clone())
}

async fn status_json(AxState(app): AxState<App>) -> impl IntoResponse {
    let s = app.status.lock().map(|s| {
        json!({
            "frames": s.frames, "frame": s.frame, "report": s.report,
            "viewers": app.viewers.load(Ordering::Relaxed),
        })
    });
    axum::Json(s.unwrap_or(Value::Null))
}

/// Handles a steering or report message; returns an error text for a bad one.
fn handle_message(app: &App, text: &str) -> Result<(), String> {
    let v: Value = serde_json::from_str(text).map_err(|e| format!("not JSON: {e}"))?;
    if let Some(report) = v.get("report") {
        if let Ok(mut s) = app.status.lock() {
            s.report = Some(report.clone());
        }
        return Ok(());
    }
    let aim = v
        .get("aim")
        .and_then(|a| serde_json::from_value::<[f64; 3]>(a.clone()).ok())
        .filter(|a| a.iter().all(|x| x.is_finite()))
        .ok_or("expected {\"aim\": [x, y, z], \"depth\": d} or {\"report\": {...}}")?;
    let depth = v
        .get("depth")
        .and_then(Value::as_f64)
        .filter(|d| d.is_finite())
        .ok_or("\"depth\" must be a finite number (m)")?;
    match &app.steer {
        Some(steer) => {
            steer(aim, depth);
            Ok(())
        }
        None => Err("this source cannot be steered (a hand holds the device)".into()),
    }
}

async fn steer_post(AxState(app): AxState<App>, body: String) -> Response {
    match handle_message(&app, &body) {
        Ok(()) => StatusCode::NO_CONTENT.into_response(),
        Err(e) => (StatusCode::BAD_REQUEST, e).into_response(),
    }
}

async fn ws_upgrade(AxState(app): AxState<App>, ws: WebSocketUpgrade) -> Response {
    ws.on_upgrade(move |socket| viewer(app, socket))
}

/// One viewer: newest frame whenever there is a new one; its messages steer or report.
async fn viewer(app: App, mut socket: WebSocket) {
    app.viewers.fetch_add(1, Ordering::Relaxed);
    let mut frames = app.frames.clone();
    frames.mark_changed();
    loop {
        tokio::select! {
            changed = frames.changed() => {
                if changed.is_err() {
                    break;
                }
                let bytes = frames.borrow_and_update().clone();
                if bytes.is_empty() {
                    continue;
                }
                let msg = Message::Binary(bytes.as_ref().clone().into());
                if socket.send(msg).await.is_err() {
                    break;
                }
            }
            msg = socket.recv() => match msg {
                Some(Ok(Message::Text(t))) => {
                    if let Err(e) = handle_message(&app, t.as_str()) {
                        let _ = socket.send(Message::Text(format!("{{\"error\": {e:?}}}").into())).await;
                    }
                }
                Some(Ok(_)) => {}
                Some(Err(_)) | None => break,
            },
        }
    }
    app.viewers.fetch_sub(1, Ordering::Relaxed);
}
