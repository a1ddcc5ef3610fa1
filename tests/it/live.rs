//! The live sinks: `--stdout`, and `--connect` to a real gRPC endpoint (rerun's message-proxy
//! service, the one a viewer serves); what arrives is what the file sink writes, and a viewer
//! that hangs up or is not there neither stops nor hangs the run.

use crate::common::{self, cellflip_in, ok, scratch_dir};
use re_protos::sdk_comms::v1alpha1::message_proxy_service_server::{
    MessageProxyService, MessageProxyServiceServer,
};
use re_protos::sdk_comms::v1alpha1::{
    ReadMessagesRequest, ReadMessagesResponse, ReadTablesRequest, ReadTablesResponse,
    WriteMessagesRequest, WriteMessagesResponse, WriteTableRequest, WriteTableResponse,
};
use rerun::external::re_log_encoding::{CachingApplicationIdInjector, Encoder, ToApplication};
use rerun::log::LogMsg;
use std::path::Path;
use std::sync::{Arc, Mutex};
use tonic::codegen::tokio_stream;
use tonic::{Request, Response, Status, Streaming};

/// The viewer's side of `WriteMessages`: keeps every message, converted as a viewer does, and
/// hangs up after `hang_up_after` messages if set (a viewer closed mid-run).
#[derive(Default, Clone)]
struct Endpoint {
    received: Arc<Mutex<Vec<LogMsg>>>,
    hang_up_after: Option<usize>,
}

type NoStream<T> = tokio_stream::Empty<Result<T, Status>>;

#[tonic::async_trait]
impl MessageProxyService for Endpoint {
    async fn write_messages(
        &self,
        request: Request<Streaming<WriteMessagesRequest>>,
    ) -> Result<Response<WriteMessagesResponse>, Status> {
        let mut stream = request.into_inner();
        let mut app_ids = CachingApplicationIdInjector::default();
        while let Some(message) = stream.message().await? {
            let proto = message
                .log_msg
                .ok_or_else(|| Status::invalid_argument("a request without a message"))?;
            let msg = proto
                .to_application((&mut app_ids, None))
                .map_err(|e| Status::invalid_argument(e.to_string()))?;
            let mut received = self.received.lock().unwrap();
            received.push(msg);
            if Some(received.len()) == self.hang_up_after {
                return Err(Status::unavailable("the viewer was closed"));
            }
        }
        Ok(Response::new(WriteMessagesResponse {}))
    }

    type ReadMessagesStream = NoStream<ReadMessagesResponse>;
    async fn read_messages(
        &self,
        _: Request<ReadMessagesRequest>,
    ) -> Result<Response<Self::ReadMessagesStream>, Status> {
        Err(Status::unimplemented("this endpoint only receives"))
    }

    async fn write_table(
        &self,
        _: Request<WriteTableRequest>,
    ) -> Result<Response<WriteTableResponse>, Status> {
        Err(Status::unimplemented("this endpoint only receives"))
    }

    type ReadTablesStream = NoStream<ReadTablesResponse>;
    async fn read_tables(
        &self,
        _: Request<ReadTablesRequest>,
    ) -> Result<Response<Self::ReadTablesStream>, Status> {
        Err(Status::unimplemented("this endpoint only receives"))
    }
}

/// Serves `endpoint` on a free loopback port while `client` runs (given the port), then stops.
fn serving<T>(endpoint: &Endpoint, client: impl FnOnce(u16) -> T) -> T {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(1)
        .enable_all()
        .build()
        .unwrap();
    let listener = runtime
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let port = listener.local_addr().unwrap().port();
    let service =
        MessageProxyServiceServer::new(endpoint.clone()).max_decoding_message_size(usize::MAX);
    let (stop, stopped) = tokio::sync::oneshot::channel::<()>();
    let server = runtime.spawn(
        tonic::transport::Server::builder().serve_with_incoming_shutdown(
            service,
            tokio_stream::wrappers::TcpListenerStream::new(listener),
            async {
                stopped.await.ok();
            },
        ),
    );
    let out = client(port);
    stop.send(()).unwrap();
    runtime.block_on(server).unwrap().unwrap();
    out
}

/// Writes messages as a recording file, so that the file helpers read them.
pub fn save(messages: &[LogMsg], path: &Path) {
    std::fs::write(path, Encoder::encode(messages.iter().map(Ok)).unwrap()).unwrap();
}

/// The run every stream test makes, with its sink's flags appended.
pub const RUN: [&str; 6] = ["run", "dam-2d", "--method", "ccp", "--steps", "4"];

/// [`RUN`] saved to a file in `dir`, the reference a stream is compared with.
pub fn saved_run(dir: &Path) -> std::path::PathBuf {
    let file = dir.join("file.rrd");
    ok(&cellflip_in(
        dir,
        &[&RUN[..], &["--save", file.to_str().unwrap()]].concat(),
    ));
    file
}

/// A streamed recording holds what the file of the same run holds: its entities, a series
/// step by step, and the blueprint's views.
pub fn assert_same_recording(streamed: &Path, file: &Path) {
    let entities = common::logged_entities(streamed);
    assert!(entities.contains("world/particles"), "{entities:?}");
    assert_eq!(entities, common::logged_entities(file));
    let entity = "metrics/correction/objective";
    let series = common::scalars_per_step(streamed, entity);
    assert_eq!(series.len(), 4, "steps 1..=4: {series:?}");
    assert_eq!(series, common::scalars_per_step(file, entity));
    assert_eq!(
        common::blueprint(streamed).0.len(),
        common::blueprint(file).0.len(),
        "the layout is streamed too"
    );
}

#[test]
fn the_stdout_stream_carries_what_the_file_holds() {
    let dir = scratch_dir("stdout_stream");
    let file = saved_run(&dir);
    let out = cellflip_in(&dir, &[&RUN[..], &["--stdout"]].concat());
    ok(&out);
    assert!(
        String::from_utf8_lossy(&out.stderr).contains("streamed to standard output"),
        "the summary goes to stderr"
    );
    let piped = dir.join("piped.rrd");
    std::fs::write(&piped, &out.stdout).unwrap();
    assert_same_recording(&piped, &file);
}

#[test]
fn the_live_sink_streams_to_a_grpc_endpoint_what_the_file_holds() {
    let dir = scratch_dir("grpc_stream");
    let file = saved_run(&dir);
    let endpoint = Endpoint::default();
    let out = serving(&endpoint, |port| {
        let url = format!("rerun+http://127.0.0.1:{port}/proxy");
        cellflip_in(&dir, &[&RUN[..], &["--connect", &url]].concat())
    });
    ok(&out);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("was lost"), "{stderr}");
    let streamed = dir.join("streamed.rrd");
    save(&endpoint.received.lock().unwrap(), &streamed);
    assert_same_recording(&streamed, &file);
}

#[test]
fn a_viewer_that_hangs_up_mid_run_neither_hangs_nor_stops_the_run() {
    let dir = scratch_dir("grpc_hang_up");
    let endpoint = Endpoint {
        hang_up_after: Some(20),
        ..Default::default()
    };
    let t0 = std::time::Instant::now();
    let out = serving(&endpoint, |port| {
        let url = format!("rerun+http://127.0.0.1:{port}/proxy");
        cellflip_in(&dir, &["run", "dam-2d", "--steps", "30", "--connect", &url])
    });
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("dam-2d (2D, ccp): 30 steps"), "{stdout}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("was lost"), "{stderr}");
    assert_eq!(endpoint.received.lock().unwrap().len(), 20);
    assert!(t0.elapsed().as_secs() < 60, "{:?}", t0.elapsed());
}

/// A viewer that is not there when the run starts: the command says so at once and exits 1
/// with nothing run (a script can tell nothing was shown); with `--no-viewer-check` the run
/// goes on, neither hangs nor fails, and says at the end that the stream was lost.
#[test]
fn a_viewer_that_is_not_there_stops_the_run_at_once_unless_asked_to_run_anyway() {
    let dir = scratch_dir("lost_viewer");
    // A port nothing listens on: bound, then released.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let url = format!("rerun+http://127.0.0.1:{port}/proxy");
    let t0 = std::time::Instant::now();
    let run = ["run", "dam-2d", "--steps", "30", "--connect", &url];
    let out = cellflip_in(&dir, &run);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(
        stderr.contains(&format!("--connect {url}: no viewer answers there")),
        "{stderr}"
    );
    assert!(out.stdout.is_empty(), "something ran");
    assert!(t0.elapsed().as_secs() < 5, "{:?}", t0.elapsed());
    let out = cellflip_in(&dir, &[&run[..], &["--no-viewer-check"]].concat());
    ok(&out);
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(stdout.contains("dam-2d (2D, ccp): 30 steps"), "{stdout}");
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("was lost"), "{stderr}");
    assert!(t0.elapsed().as_secs() < 60, "{:?}", t0.elapsed());
}
