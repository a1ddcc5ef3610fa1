//! `--serve-web` and `cellflip view`: Rerun's web viewer served over HTTP and the recording
//! over gRPC, read back by a gRPC client as a browser's viewer reads it (rerun's message-proxy
//! `ReadMessages`); what arrives is what the file of the same run holds.

use crate::common::{cellflip_in, ok, scratch_dir};
use crate::live::{assert_same_recording, save, saved_run, RUN};
use re_protos::sdk_comms::v1alpha1::message_proxy_service_client::MessageProxyServiceClient;
use re_protos::sdk_comms::v1alpha1::ReadMessagesRequest;
use rerun::external::re_log_encoding::{CachingApplicationIdInjector, ToApplication};
use rerun::log::LogMsg;
use std::io::{Read, Write};
use std::path::Path;
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

/// A loopback port nothing listens on (bound, then released).
fn free_port() -> u16 {
    let l = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    l.local_addr().unwrap().port()
}

/// `cellflip args` started in `dir`, its standard error going to `dir/stderr.txt`.
fn start(dir: &Path, args: &[&str]) -> Child {
    let err = std::fs::File::create(dir.join("stderr.txt")).unwrap();
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(args)
        .current_dir(dir)
        .stdout(Stdio::null())
        .stderr(err)
        .spawn()
        .unwrap()
}

/// Waits until the process says it goes on serving after its work (at most a minute).
fn wait_until_serving(child: &mut Child, dir: &Path) {
    let t0 = Instant::now();
    loop {
        let said = std::fs::read_to_string(dir.join("stderr.txt")).unwrap();
        if said.contains("still serving at") {
            return;
        }
        let exited = child.try_wait().unwrap();
        assert!(
            exited.is_none() && t0.elapsed().as_secs() < 60,
            "{exited:?}: {said}"
        );
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// An HTTP GET of `path` on the web port: the status line and the body.
fn http_get(port: u16, path: &str) -> (String, Vec<u8>) {
    let mut s = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap();
    write!(s, "GET {path} HTTP/1.0\r\nHost: 127.0.0.1\r\n\r\n").unwrap();
    let mut all = vec![];
    s.read_to_end(&mut all).unwrap();
    let end = all.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
    let head = String::from_utf8_lossy(&all[..end]).to_string();
    let status = head.lines().next().unwrap_or_default().to_string();
    (status, all[end + 4..].to_vec())
}

/// Everything the gRPC server at `port` holds, read as the web viewer reads it: messages until
/// none has come for two seconds.
fn read_served(port: u16) -> Vec<LogMsg> {
    let runtime = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let url = format!("http://127.0.0.1:{port}");
        let channel = tonic::transport::Endpoint::new(url)
            .unwrap()
            .connect()
            .await
            .unwrap();
        let mut client = MessageProxyServiceClient::new(channel).max_decoding_message_size(1 << 30);
        let mut stream = client
            .read_messages(ReadMessagesRequest {})
            .await
            .unwrap()
            .into_inner();
        let mut app_ids = CachingApplicationIdInjector::default();
        let mut got = vec![];
        let quiet = Duration::from_secs(2);
        while let Ok(next) = tokio::time::timeout(quiet, stream.message()).await {
            let Some(m) = next.unwrap() else { break };
            let proto = m.log_msg.expect("a message");
            got.push(proto.to_application((&mut app_ids, None)).unwrap());
        }
        got
    })
}

/// Ends a serving process with Ctrl-C: it exits 130 within a few seconds.
fn interrupt(mut child: Child) {
    let pid = child.id().to_string();
    assert!(Command::new("kill")
        .args(["-INT", &pid])
        .status()
        .unwrap()
        .success());
    let t0 = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            assert_eq!(status.code(), Some(130));
            return;
        }
        assert!(
            t0.elapsed().as_secs() < 10,
            "Ctrl-C did not end the serving"
        );
        std::thread::sleep(Duration::from_millis(50));
    }
}

/// A run served with `--serve-web` and saved with `--save`: the page and the viewer's wasm
/// answer over HTTP, a late gRPC reader gets what the file holds, and Ctrl-C ends the serving
/// (exit 130) with the file whole.
#[test]
fn a_served_run_answers_with_the_viewer_and_streams_what_its_file_holds() {
    let dir = scratch_dir("serve_web_run");
    let (web, grpc) = (free_port(), free_port());
    let (web_s, grpc_s) = (web.to_string(), grpc.to_string());
    let served = [
        "--serve-web",
        &web_s,
        "--grpc-port",
        &grpc_s,
        "--save",
        "served.rrd",
    ];
    let mut child = start(&dir, &[&RUN[..], &served].concat());
    wait_until_serving(&mut child, &dir);
    let (status, page) = http_get(web, "/");
    assert!(status.contains("200"), "{status}");
    assert!(
        String::from_utf8_lossy(&page).contains("<html"),
        "not the viewer's page"
    );
    let (status, wasm) = http_get(web, "/re_viewer_bg.wasm");
    assert!(status.contains("200"), "{status}");
    assert!(
        wasm.starts_with(b"\0asm") && wasm.len() > 10_000_000,
        "{}",
        wasm.len()
    );
    let streamed = dir.join("streamed.rrd");
    save(&read_served(grpc), &streamed);
    interrupt(child);
    let said = std::fs::read_to_string(dir.join("stderr.txt")).unwrap();
    assert!(
        said.contains(&format!(
            "open http://127.0.0.1:{web}/?url=rerun%2Bhttp://127.0.0.1:{grpc}/proxy"
        )),
        "{said}"
    );
    assert_same_recording(&streamed, &dir.join("served.rrd"));
    assert_same_recording(&dir.join("served.rrd"), &saved_run(&dir));
}

/// `cellflip view FILE --serve-web` started in `dir` on free ports, once it serves: the process
/// and its gRPC port.
fn view_served(dir: &Path, file: &str) -> (Child, u16) {
    let (web, grpc) = (free_port().to_string(), free_port());
    let grpc_s = grpc.to_string();
    let args = ["view", file, "--serve-web", &web, "--grpc-port", &grpc_s];
    let mut child = start(dir, &args);
    wait_until_serving(&mut child, dir);
    (child, grpc)
}

/// `cellflip view --serve-web` serves a saved recording: a gRPC reader gets what it holds.
#[test]
fn view_serves_a_saved_recording_to_browsers() {
    let dir = scratch_dir("serve_web_view");
    let file = saved_run(&dir);
    let (child, grpc) = view_served(&dir, file.to_str().unwrap());
    let streamed = dir.join("streamed.rrd");
    save(&read_served(grpc), &streamed);
    interrupt(child);
    assert_same_recording(&streamed, &file);
}

/// A port already taken stops the command before anything runs, naming the option and the
/// port; so does a file `view` cannot read, and `view` without a native viewer says how to
/// get one.
#[test]
fn taken_ports_missing_files_and_a_missing_viewer_are_refused_before_anything_runs() {
    let dir = scratch_dir("serve_web_refusals");
    let taken = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let port = taken.local_addr().unwrap().port().to_string();
    let free = free_port().to_string();
    for (option, args) in [
        ("--serve-web", ["--serve-web", &port, "--grpc-port", &free]),
        ("--grpc-port", ["--serve-web", &free, "--grpc-port", &port]),
    ] {
        let out = cellflip_in(&dir, &[&RUN[..], &args].concat());
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains(&format!(
                "{option} {port}: cannot listen on 127.0.0.1:{port}"
            )),
            "{stderr}"
        );
        assert!(out.stdout.is_empty(), "something ran");
    }
    let out = cellflip_in(&dir, &["view", "nowhere.rrd", "--serve-web", &free]);
    assert_eq!(out.status.code(), Some(1));
    assert!(String::from_utf8_lossy(&out.stderr).contains("cannot open recording 'nowhere.rrd'"));
    let file = saved_run(&dir);
    let out = Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .args(["view", file.to_str().unwrap()])
        .env("PATH", "/nonexistent")
        .output()
        .unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{stderr}");
    assert!(stderr.contains("cellflip view --serve-web"), "{stderr}");
    let out = cellflip_in(&dir, &[&RUN[..], &["--serve-web", "--spawn"]].concat());
    assert_eq!(
        out.status.code(),
        Some(1),
        "--serve-web with --spawn is a usage error"
    );
    ok(&cellflip_in(&dir, &["view", "--help"]));
}

/// `cellflip view FILES` with `PATH` holding no viewer: what it says of the files before it
/// looks for one (then it fails, saying there is none).
fn view_without_viewer(dir: &Path, files: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_cellflip"))
        .arg("view")
        .args(files)
        .current_dir(dir)
        .env("PATH", "/nonexistent")
        .output()
        .unwrap()
}

/// `view` reads every file through before it serves or opens a viewer: a file that is not a
/// recording is refused (exit 1, naming it, no URL announced), in a browser or natively, and
/// what `run`, `compare` and `report` write passes without a word.
#[test]
fn view_refuses_a_file_that_is_not_a_recording_before_serving() {
    let dir = scratch_dir("serve_web_not_a_recording");
    std::fs::write(dir.join("text.rrd"), "plain text, named like a recording\n").unwrap();
    let free = free_port().to_string();
    let served = cellflip_in(&dir, &["view", "text.rrd", "--serve-web", &free]);
    let native = view_without_viewer(&dir, &["text.rrd"]);
    for out in [served, native] {
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{stderr}");
        assert!(
            stderr.contains("error: cannot read recording 'text.rrd': it is not a Rerun recording"),
            "{stderr}"
        );
        assert!(
            !stderr.contains("serving") && !stderr.contains("no native viewer"),
            "{stderr}"
        );
    }
    saved_run(&dir);
    let compare = ["compare", "dam-2d", "--methods", "flip,ccp", "--res", "24"];
    let short = ["--duration", "0.05", "--save", "compare.rrd"];
    ok(&cellflip_in(&dir, &[&compare[..], &short].concat()));
    let report = [
        "report",
        "--scenes",
        "dam-2d",
        "--methods",
        "flip",
        "--res",
        "24",
    ];
    let short = [
        "--duration",
        "0.05",
        "--no-stability",
        "-q",
        "--out",
        "report",
    ];
    ok(&cellflip_in(&dir, &[&report[..], &short].concat()));
    let out = view_without_viewer(&dir, &["file.rrd", "compare.rrd", "report/report.rrd"]);
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.starts_with("error: no native viewer"), "{stderr}");
}

/// A recording cut at half its bytes is served as far as it can be read, with a warning that
/// says up to which step it holds and why the rest cannot be read.
#[test]
fn view_serves_a_recording_cut_short_with_a_warning() {
    let dir = scratch_dir("serve_web_cut_short");
    let whole = std::fs::read(saved_run(&dir)).unwrap();
    std::fs::write(dir.join("half.rrd"), &whole[..whole.len() / 2]).unwrap();
    let (child, grpc) = view_served(&dir, "half.rrd");
    let served = read_served(grpc);
    interrupt(child);
    let held = cellflip::record::Contents::read(&dir.join("half.rrd")).unwrap();
    assert!(held.messages > 0 && held.messages < messages_in(&whole));
    assert_eq!(served.len(), held.messages);
    let said = std::fs::read_to_string(dir.join("stderr.txt")).unwrap();
    let warning = "warning: 'half.rrd' is cut short: it holds steps 0..=";
    assert!(said.contains(warning), "{said}");
    assert!(
        said.contains(" (the rest could not be read: it stops "),
        "{said}"
    );
    let native = view_without_viewer(&dir, &["half.rrd"]);
    assert!(String::from_utf8_lossy(&native.stderr).starts_with(warning));
}

/// The messages a whole recording holds.
fn messages_in(rrd: &[u8]) -> usize {
    use rerun::external::re_log_encoding::DecoderApp;
    DecoderApp::decode_lazy(rrd).map(Result::unwrap).count()
}

/// A run resumed from a checkpoint goes on in its file and is served whole: browsers get the
/// steps before the checkpoint too, with the layout and static data sent once.
#[test]
fn a_resumed_run_is_served_from_its_start() {
    let dir = scratch_dir("serve_web_resume");
    let two = ["run", "dam-2d", "--method", "ccp", "--steps", "2"];
    let saving = ["--save", "served.rrd", "--checkpoint-every", "10"];
    ok(&cellflip_in(&dir, &[&two[..], &saving].concat()));
    let (web, grpc) = (free_port(), free_port());
    let (web_s, grpc_s) = (web.to_string(), grpc.to_string());
    let resume = ["run", "--resume", "served.checkpoints", "--steps", "4"];
    let served = ["--serve-web", &web_s, "--grpc-port", &grpc_s];
    let mut child = start(&dir, &[&resume[..], &served].concat());
    wait_until_serving(&mut child, &dir);
    let streamed = dir.join("streamed.rrd");
    save(&read_served(grpc), &streamed);
    interrupt(child);
    assert_same_recording(&streamed, &dir.join("served.rrd"));
    assert_same_recording(&streamed, &saved_run(&dir));
}
