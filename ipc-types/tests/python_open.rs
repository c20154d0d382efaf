//! The Python client opens services as the Rust processes do (`python/mems_ipc.py`,
//! `open_service`): a service whose creator stopped half way for longer than iceoryx2's 1 s
//! `creation_timeout` is opened once that creator is gone, not refused as hanging in creation
//! (as `ipc_types::service`'s unit test `a_service_hanging_in_creation_is_waited_for` checks
//! for Rust). Needs python3 with the iceoryx2 Python package (0.10): it skips, loudly, without
//! it, except under CI (`.ci/run` installs it).

mod python_run;

use iceoryx2::prelude::Config;
use python_run::run_python;
use std::process::Command;

/// Creates the service once to find its static config (the file that names it) and drops it;
/// leaves that file at iceoryx2's init permissions (owner read-write, iceoryx2-cal's
/// `static_storage/file.rs`, `INIT_PERMISSIONS`), as a creator stopped half way does, removes
/// it after 2.5 s and opens the service meanwhile.
const SCRIPT: &str = r#"
import glob, os, sys, threading
sys.path.insert(0, sys.argv[1])
import iceoryx2 as iox2
import mems_ipc

iox2.set_log_level_from_env_or(iox2.LogLevel.Error)
node = iox2.NodeBuilder.new().create(iox2.ServiceType.Ipc)
name = f"python-hang-{os.getpid()}/" + mems_ipc.SERVICE_RAW
service = mems_ipc.open_service(node, name, mems_ipc.RawImuSample)
found = [p for p in glob.glob(os.path.join(sys.argv[2], "*.service"))
         if name in open(p, errors="ignore").read()]
assert len(found) == 1, found
del service
assert not os.path.exists(found[0]), f"{found[0]} left behind"
open(found[0], "w").close()
os.chmod(found[0], 0o600)
creator_gone = threading.Timer(2.5, os.remove, [found[0]])
creator_gone.start()
mems_ipc.open_service(node, name, mems_ipc.RawImuSample)
creator_gone.join()
print("opened")
"#;

#[test]
fn python_waits_for_a_service_hanging_in_creation() {
    let importable = Command::new("python3")
        .args(["-c", "import iceoryx2"])
        .status()
        .is_ok_and(|s| s.success());
    if !importable {
        assert!(
            std::env::var_os("CI").is_none(),
            "python3 cannot import the iceoryx2 Python package under CI"
        );
        eprintln!("SKIPPED: python3 cannot import the iceoryx2 Python package (0.10)");
        return;
    }
    let services = Config::global_config().global.service_dir().to_string();
    let out = run_python(SCRIPT, &[&services]);
    assert_eq!(out.trim(), "opened");
}
