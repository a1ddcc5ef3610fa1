//! Serving a recording to browsers (`--serve-web`): Rerun's web viewer over HTTP and the
//! recording over gRPC, the way `rerun --serve-web` does, so that a class needs only a browser.
//!
//! The gRPC server (rerun's message proxy) keeps what was logged, up to its memory limit, so a
//! browser that opens the page late still gets the whole run; past the limit it drops the
//! oldest non-static data. Serving goes on after the run until Ctrl-C ([`Served::hold_until_signal`]).

use super::{Contents, RecordError};
use rerun::sink::LogSink;
use std::net::{IpAddr, TcpListener};
use std::time::Duration;

/// Where and how the web viewer is served.
#[derive(Clone, Debug, PartialEq)]
pub struct WebServe {
    /// The web viewer's HTTP port.
    pub web_port: u16,
    /// The recording's gRPC port.
    pub grpc_port: u16,
    /// The address both listen on (127.0.0.1 unless `--bind` says otherwise).
    pub bind: IpAddr,
    /// The gRPC server's memory limit, as rerun parses it ("1GiB", "25%").
    pub memory_limit: String,
}

/// `--server-memory-limit`: a size ("1GiB", "500MB") or a share of the machine's memory ("25%").
pub fn parse_memory_limit(s: &str) -> Result<String, String> {
    rerun::MemoryLimit::parse(s).map(|_| s.to_string())
}

impl WebServe {
    /// The address to open: the bound one, or this machine's loopback one when bound to all
    /// (another machine puts this one's address in its place, in both places).
    pub fn url(&self) -> String {
        let host = match self.bind {
            IpAddr::V4(a) if a.is_unspecified() => "127.0.0.1".to_string(),
            IpAddr::V6(a) if a.is_unspecified() => "[::1]".to_string(),
            IpAddr::V6(a) => format!("[{a}]"),
            a => a.to_string(),
        };
        format!(
            "http://{host}:{}/?url=rerun%2Bhttp://{host}:{}/proxy",
            self.web_port, self.grpc_port
        )
    }

    /// Fails, naming the option and the address, when a port is taken (checked by binding it:
    /// rerun's gRPC server binds on a thread of its own and would only log the failure).
    pub fn check_ports(&self) -> Result<(), RecordError> {
        if self.web_port == self.grpc_port {
            return Err(RecordError::Option {
                option: format!("--serve-web {0} and --grpc-port {0}", self.web_port),
                error: "the web viewer and the recording need two ports".into(),
            });
        }
        for (option, port) in [
            ("--serve-web", self.web_port),
            ("--grpc-port", self.grpc_port),
        ] {
            if let Err(e) = TcpListener::bind((self.bind, port)) {
                return Err(RecordError::Option {
                    option: format!("{option} {port}"),
                    error: format!(
                        "cannot listen on {}:{port} ({e}); is another viewer or cellflip serving \
                         there? Choose another port with {option} PORT",
                        self.bind
                    )
                    .into(),
                });
            }
        }
        Ok(())
    }

    /// Starts both servers and gives the sink that feeds them; says where to point a browser,
    /// and warns when they listen beyond this machine.
    pub fn start(&self) -> Result<Box<dyn LogSink>, RecordError> {
        self.check_ports()?;
        let option = |name: &str, value: &dyn std::fmt::Display| format!("{name} {value}");
        let mut options = rerun::ServerOptions {
            memory_limit: rerun::MemoryLimit::parse(&self.memory_limit).map_err(|e| {
                RecordError::Option {
                    option: option("--server-memory-limit", &self.memory_limit),
                    error: e.into(),
                }
            })?,
            ..Default::default()
        };
        if !self.bind.is_loopback() {
            // The recording's server answers the viewer's page only from allowed origins:
            // localhost's by default, and the bound address's here (any, when bound to all).
            options.cors_allowed_origins = match self.bind.is_unspecified() {
                true => vec!["*".into()],
                false => vec![format!("*://{}", self.bind), format!("*://{}:*", self.bind)],
            };
            eprintln!(
                "warning: --bind {}: the run is served to every machine that can reach this one \
                 on ports {} and {}, without a password",
                self.bind, self.web_port, self.grpc_port
            );
            if self.bind.is_unspecified() {
                eprintln!(
                    "other machines open the URL below with this machine's address in place of its \
                     host (127.0.0.1 or [::1]), in both places"
                );
            }
        }
        let sink = rerun::web_viewer::new_sink(
            false,
            &self.bind.to_string(),
            self.web_port.into(),
            None,
            self.grpc_port,
            options,
        )
        .map_err(|e| RecordError::Option {
            option: option("--serve-web", &self.web_port),
            error: e.into(),
        })?;
        eprintln!("serving the web viewer: open {}", self.url());
        Ok(sink)
    }
}

/// What keeps a served recording served once it is written: the stream that holds the servers.
pub struct Served {
    keep: Box<dyn Send>,
    url: String,
}

impl Served {
    /// Holds `keep` (the stream, or the sink) that holds the servers announced at `url`.
    pub fn new(keep: impl Send + 'static, url: String) -> Self {
        Self {
            keep: Box::new(keep),
            url,
        }
    }

    /// Serves until a signal stops the process (Ctrl-C: [`crate::interrupt`]), polling ten
    /// times a second; the servers close when this returns.
    pub fn hold_until_signal(self) {
        let stop = || crate::interrupt::signal().is_some();
        if !stop() {
            eprintln!(
                "still serving at {} so that late browsers see the whole recording; Ctrl-C ends it",
                self.url
            );
        }
        while !stop() {
            std::thread::sleep(Duration::from_millis(100));
        }
        drop(self.keep);
    }
}

/// Serves saved recordings as `serve` says: each file's messages that [`Contents::read`]
/// found whole, in order, go to the servers before the page is announced as ready (of a file
/// cut short, those before the cut). Fails, naming the file, on one that can no longer be read.
pub fn serve_files(serve: &WebServe, files: &[Contents]) -> Result<Served, RecordError> {
    use rerun::external::re_log_encoding::DecoderApp;
    let sink = serve.start()?;
    for c in files {
        let cannot = |error: crate::out::BoxError| RecordError::Read {
            path: c.path.clone(),
            error,
        };
        let file = std::fs::File::open(&c.path).map_err(|e| cannot(e.into()))?;
        let messages = DecoderApp::decode_lazy(std::io::BufReader::new(file));
        for msg in messages.take(c.messages) {
            sink.send(msg.map_err(|e| cannot(e.into()))?);
        }
    }
    sink.flush_blocking(Duration::from_secs(60))
        .map_err(|e| RecordError::Serve(e.into()))?;
    Ok(Served::new(sink, serve.url()))
}
