//! Shared helpers of the tests that run the `dynbvh` binary: a fresh folder, a run, its
//! checked output, the shipped animations.
#![allow(dead_code)]

use std::ffi::OsStr;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};

/// A fresh, empty temporary folder named after the test binary's `prefix` and `name`,
/// removed with everything in it when dropped (a failing test's folder is kept to look at).
pub fn tmp_dir(prefix: &str, name: &str) -> TmpDir {
    let d = std::env::temp_dir().join(format!("dynbvh_{prefix}_{}_{name}", std::process::id()));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    TmpDir(d)
}

/// A folder of [`tmp_dir`]: a path while it lives.
pub struct TmpDir(PathBuf);

impl std::ops::Deref for TmpDir {
    type Target = PathBuf;
    fn deref(&self) -> &PathBuf {
        &self.0
    }
}

impl AsRef<Path> for TmpDir {
    fn as_ref(&self) -> &Path {
        &self.0
    }
}

impl AsRef<OsStr> for TmpDir {
    fn as_ref(&self) -> &OsStr {
        self.0.as_os_str()
    }
}

impl Drop for TmpDir {
    fn drop(&mut self) {
        if !std::thread::panicking() {
            let _ = std::fs::remove_dir_all(&self.0);
        }
    }
}

/// Runs the built `dynbvh` binary with `args`.
pub fn dynbvh<S: AsRef<OsStr>>(args: &[S]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_dynbvh"))
        .args(args)
        .output()
        .expect("run dynbvh")
}

/// Stdout of a successful run (panics with stderr otherwise).
pub fn ok(o: &Output) -> String {
    assert!(
        o.status.success(),
        "dynbvh failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// The path of a shipped animation in `animations/`.
pub fn animation(name: &str) -> String {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("animations")
        .join(name)
        .to_string_lossy()
        .into_owned()
}
