//! The headless browser the web test drives: Debian's `chromium`, found on
//! the PATH or installed on first use (`apt-get install chromium`, as root),
//! so a newcomer's `cargo test` needs nothing installed by hand.

use std::path::PathBuf;
use std::process::Command;
use std::sync::Mutex;

/// Where Chromium's executable is, installing it when it is missing.
/// Panics, saying what failed and how to fix it, when it cannot be had.
pub(crate) fn chromium() -> PathBuf {
    static INSTALLING: Mutex<()> = Mutex::new(());
    let _installing = INSTALLING.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(found) = on_path() {
        return found;
    }
    for step in [
        &["apt-get", "update", "-qq"][..],
        &["apt-get", "install", "-y", "-qq", "chromium"][..],
    ] {
        let output = Command::new(step[0])
            .args(&step[1..])
            .env("DEBIAN_FRONTEND", "noninteractive")
            .output()
            .unwrap_or_else(|e| {
                panic!(
                    "chromium is not installed and `{}` cannot start: {e}",
                    step.join(" ")
                )
            });
        assert!(
            output.status.success(),
            "chromium is not installed and `{}` failed (install Debian's `chromium` as root): {}",
            step.join(" "),
            String::from_utf8_lossy(&output.stderr)
        );
    }
    on_path().expect("chromium is on the PATH after `apt-get install chromium`")
}

fn on_path() -> Option<PathBuf> {
    let path = std::env::var_os("PATH")?;
    std::env::split_paths(&path)
        .map(|dir| dir.join("chromium"))
        .find(|candidate| candidate.is_file())
}

/// Headless Chromium driven over the DevTools protocol (its WebSocket
/// JSON-RPC, <https://chromedevtools.github.io/devtools-protocol/>): the
/// three calls the web test makes — open a page, evaluate a script, take
/// a screenshot — each blocking on the browser's answer. A handful of
/// JSON messages, so the test needs a WebSocket client, not a generated
/// binding of the whole protocol (that one cost minutes of every cold
/// build).
pub struct Chromium {
    child: std::process::Child,
    port: u16,
    browser: Socket,
    page: Option<Socket>,
    next_id: u64,
}

type Socket = tungstenite::WebSocket<tungstenite::stream::MaybeTlsStream<std::net::TcpStream>>;

/// How long one answer of the browser may take.
const PATIENCE: std::time::Duration = std::time::Duration::from_secs(60);

impl Chromium {
    /// Starts Chromium headless with a fresh profile under `dir`, its
    /// window `width` × `height` CSS pixels.
    pub fn start(dir: &std::path::Path, width: u32, height: u32) -> Chromium {
        let profile = dir.join(format!("chromium-profile-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&profile);
        std::fs::create_dir_all(&profile).expect("a profile folder");
        let child = Command::new(chromium())
            .arg("--headless")
            .arg("--remote-debugging-port=0")
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg(format!("--window-size={width},{height}"))
            .args([
                "--no-sandbox",
                "--disable-gpu",
                "--disable-quic",
                "--no-first-run",
                "--disable-background-networking",
                "--disable-component-update",
                "--disable-sync",
                "about:blank",
            ])
            .stdout(std::process::Stdio::null())
            .stderr(std::process::Stdio::null())
            .spawn()
            .expect("chromium starts (apt-get install chromium)");
        // Chromium writes the port it chose and the browser's WebSocket
        // path into the profile once it listens.
        let active = profile.join("DevToolsActivePort");
        let started = std::time::Instant::now();
        let (port, path) = loop {
            let text = std::fs::read_to_string(&active).unwrap_or_default();
            let mut lines = text.lines();
            if let (Some(port), Some(path)) = (lines.next(), lines.next()) {
                if let Ok(port) = port.trim().parse::<u16>() {
                    break (port, path.trim().to_string());
                }
            }
            assert!(
                started.elapsed() < PATIENCE,
                "chromium never wrote {}",
                active.display()
            );
            std::thread::sleep(std::time::Duration::from_millis(50));
        };
        let browser = connect(&format!("ws://127.0.0.1:{port}{path}"));
        Chromium {
            child,
            port,
            browser,
            page: None,
            next_id: 0,
        }
    }

    /// Opens `url` in a new tab and waits until it has loaded.
    pub fn open(&mut self, url: &str) {
        let target = self
            .call(
                false,
                "Target.createTarget",
                serde_json::json!({ "url": url }),
            )
            .unwrap_or_else(|e| panic!("opening {url}: {e}"));
        let target = target["targetId"].as_str().expect("a target id");
        self.page = Some(connect(&format!(
            "ws://127.0.0.1:{}/devtools/page/{target}",
            self.port
        )));
        // The new tab starts at about:blank, itself "complete" at once.
        let loaded = format!(
            "String(location.href.startsWith({}) && document.readyState === 'complete')",
            serde_json::Value::from(url)
        );
        let started = std::time::Instant::now();
        while self.eval(&loaded) != "true" {
            assert!(started.elapsed() < PATIENCE, "{url} never loaded");
            std::thread::sleep(std::time::Duration::from_millis(50));
        }
    }

    /// The value of a JavaScript expression that gives a string.
    pub fn eval(&mut self, js: &str) -> String {
        let answer = self
            .call(
                true,
                "Runtime.evaluate",
                serde_json::json!({ "expression": js, "returnByValue": true, "awaitPromise": true }),
            )
            .unwrap_or_else(|e| panic!("{js}: {e}"));
        if let Some(thrown) = answer.get("exceptionDetails") {
            panic!("{js} threw: {thrown}");
        }
        match answer["result"]["value"].as_str() {
            Some(value) => value.to_string(),
            None => panic!("{js} is not a string: {}", answer["result"]),
        }
    }

    /// A PNG of the open page.
    pub fn screenshot(&mut self) -> Vec<u8> {
        use base64::Engine;
        let answer = self
            .call(
                true,
                "Page.captureScreenshot",
                serde_json::json!({ "format": "png" }),
            )
            .unwrap_or_else(|e| panic!("a screenshot: {e}"));
        let data = answer["data"].as_str().expect("the screenshot's data");
        base64::engine::general_purpose::STANDARD
            .decode(data)
            .expect("the screenshot is base64")
    }

    /// One call to the open page (`on_page`) or to the browser, under
    /// the next message id.
    fn call(
        &mut self,
        on_page: bool,
        method: &str,
        params: serde_json::Value,
    ) -> Result<serde_json::Value, String> {
        self.next_id += 1;
        let socket = if on_page {
            self.page.as_mut().expect("a page is open")
        } else {
            &mut self.browser
        };
        call(socket, self.next_id, method, params)
    }
}

impl Drop for Chromium {
    fn drop(&mut self) {
        let _ = self.call(false, "Browser.close", serde_json::Value::Null);
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn connect(url: &str) -> Socket {
    let (socket, _) = tungstenite::connect(url).unwrap_or_else(|e| panic!("{url}: {e}"));
    if let tungstenite::stream::MaybeTlsStream::Plain(stream) = socket.get_ref() {
        // A browser that stops answering fails the test, never hangs it.
        stream
            .set_read_timeout(Some(PATIENCE))
            .expect("a read timeout");
    }
    socket
}

/// Sends one call and reads until its answer (events the browser sends
/// meanwhile are skipped): the result, or the browser's error message.
fn call(
    socket: &mut Socket,
    id: u64,
    method: &str,
    params: serde_json::Value,
) -> Result<serde_json::Value, String> {
    let mut message = serde_json::json!({ "id": id, "method": method });
    if !params.is_null() {
        message["params"] = params;
    }
    socket
        .send(tungstenite::Message::text(message.to_string()))
        .map_err(|e| format!("{method}: {e}"))?;
    loop {
        let text = match socket.read().map_err(|e| format!("{method}: {e}"))? {
            tungstenite::Message::Text(text) => text,
            _ => continue,
        };
        let answer: serde_json::Value =
            serde_json::from_str(&text).map_err(|e| format!("{method}: {e}: {text}"))?;
        if answer["id"] != id {
            continue;
        }
        return match answer.get("error") {
            Some(error) => Err(format!("{method}: {error}")),
            None => Ok(answer["result"].clone()),
        };
    }
}
