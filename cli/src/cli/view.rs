//! `scode view`: a minimal localhost HTTP server for the WebGL viewer page (`viewer/`) and one
//! `.scode` file. The page, its script and the WebAssembly module are compiled into the
//! binary (`include_bytes!` of the committed `viewer/` files, which `viewer/build.sh`
//! regenerates), so the command needs nothing at run time and `cargo build` needs no wasm
//! toolchain.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{Ipv4Addr, TcpListener, TcpStream};
use std::path::{Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};

/// The viewer's files: (URL path, content type, bytes).
const ASSETS: &[(&str, &str, &[u8])] = &[
    (
        "/",
        "text/html; charset=utf-8",
        include_bytes!("../../../viewer/index.html"),
    ),
    (
        "/index.html",
        "text/html; charset=utf-8",
        include_bytes!("../../../viewer/index.html"),
    ),
    (
        "/viewer.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../../viewer/viewer.js"),
    ),
    (
        "/pkg/scode_wasm.js",
        "text/javascript; charset=utf-8",
        include_bytes!("../../../viewer/pkg/scode_wasm.js"),
    ),
    (
        "/pkg/scode_wasm_bg.wasm",
        "application/wasm",
        include_bytes!("../../../viewer/pkg/scode_wasm_bg.wasm"),
    ),
];

/// What `scode view` serves: the embedded viewer and `file` under `/files/<name>`.
pub struct ViewServer {
    listener: TcpListener,
    file: PathBuf,
    file_url: String,
}

impl ViewServer {
    /// Binds 127.0.0.1:`port` (0: any free port). The file must exist and be readable.
    pub fn bind(file: &Path, port: u16) -> Result<ViewServer> {
        std::fs::metadata(file).with_context(|| format!("cannot read {}", file.display()))?;
        let name = file
            .file_name()
            .map(|n| n.to_string_lossy().into_owned())
            .unwrap_or_else(|| "model.scode".into());
        let safe: String = name
            .chars()
            .map(|c| {
                if c.is_ascii_alphanumeric() || "._-".contains(c) {
                    c
                } else {
                    '_'
                }
            })
            .collect();
        let listener = TcpListener::bind((Ipv4Addr::LOCALHOST, port))
            .with_context(|| format!("cannot listen on 127.0.0.1:{port} (try --port 0)"))?;
        Ok(ViewServer {
            listener,
            file: file.to_path_buf(),
            file_url: format!("/files/{safe}"),
        })
    }

    /// The page URL that opens the file.
    pub fn url(&self) -> Result<String> {
        let addr = self.listener.local_addr()?;
        Ok(format!("http://{addr}/?file={}", self.file_url))
    }

    /// Serves until the process is stopped; one short-lived thread per connection.
    pub fn serve(self) -> Result<()> {
        for stream in self.listener.incoming() {
            let Ok(stream) = stream else { continue };
            let file = self.file.clone();
            let file_url = self.file_url.clone();
            std::thread::spawn(move || {
                // A client that disconnects or sends garbage only ends its own connection.
                let _ = handle(stream, &file, &file_url);
            });
        }
        Ok(())
    }
}

fn handle(mut stream: TcpStream, file: &Path, file_url: &str) -> Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(10)))?;
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut request_line = String::new();
    reader.by_ref().take(8192).read_line(&mut request_line)?;
    // Skip the headers (bounded).
    let mut header_bytes = 0usize;
    loop {
        let mut line = String::new();
        let n = reader.by_ref().take(8192).read_line(&mut line)?;
        header_bytes += n;
        if n == 0 || line == "\r\n" || line == "\n" || header_bytes > 65536 {
            break;
        }
    }
    let mut parts = request_line.split_whitespace();
    let (method, target) = (parts.next().unwrap_or(""), parts.next().unwrap_or(""));
    let path = target.split(['?', '#']).next().unwrap_or("");
    if method != "GET" && method != "HEAD" {
        return respond(
            &mut stream,
            "405 Method Not Allowed",
            "text/plain",
            b"GET only\n",
            true,
        );
    }
    let head_only = method == "HEAD";
    if path == file_url {
        return match std::fs::read(file) {
            Ok(bytes) => respond(
                &mut stream,
                "200 OK",
                "application/octet-stream",
                &bytes,
                !head_only,
            ),
            Err(e) => respond(
                &mut stream,
                "500 Internal Server Error",
                "text/plain",
                format!("cannot read {}: {e}\n", file.display()).as_bytes(),
                !head_only,
            ),
        };
    }
    match ASSETS.iter().find(|(p, _, _)| *p == path) {
        Some((_, ctype, bytes)) => respond(&mut stream, "200 OK", ctype, bytes, !head_only),
        None => respond(
            &mut stream,
            "404 Not Found",
            "text/plain",
            b"not found\n",
            !head_only,
        ),
    }
}

fn respond(
    stream: &mut TcpStream,
    status: &str,
    content_type: &str,
    body: &[u8],
    send_body: bool,
) -> Result<()> {
    write!(
        stream,
        "HTTP/1.1 {status}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Cache-Control: no-store\r\nConnection: close\r\n\r\n",
        body.len()
    )?;
    if send_body {
        stream.write_all(body)?;
    }
    stream.flush()?;
    Ok(())
}

/// Asks the desktop to open `url` in a browser; failures are reported, not fatal.
pub fn open_browser(url: &str) {
    let opener = if cfg!(target_os = "macos") {
        "open"
    } else if cfg!(target_os = "windows") {
        "explorer"
    } else {
        "xdg-open"
    };
    if let Err(e) = std::process::Command::new(opener)
        .arg(url)
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::null())
        .spawn()
    {
        eprintln!("could not start {opener} ({e}); open the URL yourself");
    }
}

/// Checks the file is a `.scode` file before serving it, so a wrong argument fails early.
pub fn check_scode(file: &Path) -> Result<()> {
    let mut magic = Vec::new();
    std::fs::File::open(file)
        .and_then(|f| f.take(4).read_to_end(&mut magic))
        .with_context(|| format!("cannot read {}", file.display()))?;
    if magic != scode::codec::MAGIC {
        bail!(
            "{} is not a .scode file (encode a mesh first: scode encode in.obj out.scode)",
            file.display()
        );
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::io::Read;

    fn get(addr: std::net::SocketAddr, path: &str) -> (String, Vec<u8>) {
        let mut s = TcpStream::connect(addr).unwrap();
        write!(s, "GET {path} HTTP/1.1\r\nHost: x\r\n\r\n").unwrap();
        let mut buf = Vec::new();
        s.read_to_end(&mut buf).unwrap();
        let split = buf.windows(4).position(|w| w == b"\r\n\r\n").unwrap();
        (
            String::from_utf8_lossy(&buf[..split]).into_owned(),
            buf[split + 4..].to_vec(),
        )
    }

    #[test]
    fn serves_the_page_the_module_and_the_file_only() {
        let dir = std::env::temp_dir().join(format!("scode-view-test-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("my part.scode");
        std::fs::write(&file, b"SCOD-test-bytes").unwrap();
        let server = ViewServer::bind(&file, 0).unwrap();
        let url = server.url().unwrap();
        assert!(url.ends_with("/?file=/files/my_part.scode"), "{url}");
        let addr = server.listener.local_addr().unwrap();
        std::thread::spawn(move || server.serve());
        let (h, body) = get(addr, "/?file=/files/my_part.scode");
        assert!(h.starts_with("HTTP/1.1 200"), "{h}");
        assert!(String::from_utf8_lossy(&body).contains("viewer.js"));
        let (h, body) = get(addr, "/pkg/scode_wasm_bg.wasm");
        assert!(h.contains("application/wasm"));
        assert_eq!(&body[..4], b"\0asm");
        let (h, body) = get(addr, "/files/my_part.scode");
        assert!(h.starts_with("HTTP/1.1 200"));
        assert_eq!(body, b"SCOD-test-bytes");
        let (h, _) = get(addr, "/files/../Cargo.toml");
        assert!(h.starts_with("HTTP/1.1 404"), "{h}");
        let (h, _) = get(addr, "/etc/passwd");
        assert!(h.starts_with("HTTP/1.1 404"), "{h}");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn refuses_files_that_are_not_scode() {
        let dir = std::env::temp_dir().join(format!("scode-view-check-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let f = dir.join("x.obj");
        std::fs::write(&f, b"v 0 0 0\n").unwrap();
        assert!(check_scode(&f).is_err());
        assert!(check_scode(&dir.join("missing.scode")).is_err());
        std::fs::remove_dir_all(&dir).ok();
    }
}
