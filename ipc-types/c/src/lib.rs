//! The C API of mems-odometry's clients (`libmems_client.so`, declared in
//! `ipc-types/include/mems_client.h`): a C program subscribes to the odometry state, sleeps on
//! the service's event until the odometry publishes (as the Rust and Python clients do), and
//! takes the states, zero-copy up to the copy into the caller's `mems_odometry_state`.
//!
//! Hand-written because iceoryx2's own C bindings are not published for our iceoryx2 release
//! (crates.io's last C FFI crate is `iceoryx2-ffi` 0.4.1); this is the small part a client
//! needs, over the same Rust functions every process uses (`ipc_types::service`,
//! `ipc_types::wake`), so the C client opens the service exactly as they do.
//!
//! Errors: a function that fails returns NULL or -1 and leaves a message for
//! [`mems_last_error`] (per thread). SIGINT/SIGTERM are caught ([`ipc_types::stop`]): a wait
//! then returns -2, so a client's loop ends cleanly.

use std::cell::RefCell;
use std::ffi::{CStr, CString, c_char};
use std::time::Duration;

use iceoryx2::port::listener::Listener;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::prelude::*;
use ipc_types::service::{self, ServiceError};
use ipc_types::wake::{self, WaitMode};
use ipc_types::{OdometryState, stop};

/// A subscription to `mems/odometry/state` with the listener of its event.
pub struct MemsOdometrySubscriber {
    subscriber: Subscriber<ipc::Service, OdometryState, ()>,
    listener: Listener<ipc::Service>,
    // Dropped last: the ports belong to it.
    _node: Node<ipc::Service>,
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(message: &str) {
    let text = CString::new(message.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = text);
}

fn open(namespace: Option<&str>) -> Result<MemsOdometrySubscriber, ServiceError> {
    stop::install()?;
    let node = service::node()?;
    let name = service::full_name(&service::namespace(namespace), service::ODOMETRY);
    let subscriber = service::subscriber(&service::open::<OdometryState>(&node, &name)?)?;
    let listener = wake::listener(&node, &name, WaitMode::Event)?
        .ok_or_else(|| ServiceError(format!("no listener on {name}")))?;
    Ok(MemsOdometrySubscriber {
        subscriber,
        listener,
        _node: node,
    })
}

/// Subscribes to the odometry state in `namespace` (NULL: `$MEMS_NAMESPACE`, else none).
/// Returns NULL on error (see [`mems_last_error`]).
///
/// # Safety
/// `namespace` is NULL or a NUL-terminated string.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn mems_odometry_subscribe(
    namespace: *const c_char,
) -> *mut MemsOdometrySubscriber {
    let namespace = if namespace.is_null() {
        None
    } else {
        // SAFETY: the caller passes a NUL-terminated string.
        match unsafe { CStr::from_ptr(namespace) }.to_str() {
            Ok(s) => Some(s),
            Err(_) => {
                set_error("namespace is not UTF-8");
                return std::ptr::null_mut();
            }
        }
    };
    match open(namespace) {
        Ok(s) => Box::into_raw(Box::new(s)),
        Err(e) => {
            set_error(&e.to_string());
            std::ptr::null_mut()
        }
    }
}

/// Sleeps until the odometry has published since the last wait, at most `timeout_ms`.
/// Returns 1 when woken by a publication, 0 on timeout, -2 once SIGINT or SIGTERM has
/// arrived, -1 on error. Then take the states with [`mems_odometry_receive`] until it
/// returns 0: a publication after that wakes the next wait at once.
///
/// # Safety
/// `sub` comes from [`mems_odometry_subscribe`] and was not unsubscribed.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn mems_odometry_wait(
    sub: *mut MemsOdometrySubscriber,
    timeout_ms: u32,
) -> i32 {
    // SAFETY: the caller's contract.
    let Some(sub) = (unsafe { sub.as_ref() }) else {
        set_error("NULL subscriber");
        return -1;
    };
    if stop::requested() {
        return -2;
    }
    let result = sub
        .listener
        .timed_wait(|_| {}, Duration::from_millis(u64::from(timeout_ms)));
    match result {
        _ if stop::requested() => -2,
        Ok(0) => 0,
        Ok(_) => 1,
        Err(e) => {
            set_error(&format!("waiting on the odometry's event: {e:?}"));
            -1
        }
    }
}

/// Takes the next odometry state into `*out`: 1 if one was waiting, 0 if none, -1 on error.
///
/// # Safety
/// `sub` comes from [`mems_odometry_subscribe`]; `out` points to a `mems_odometry_state`.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn mems_odometry_receive(
    sub: *mut MemsOdometrySubscriber,
    out: *mut OdometryState,
) -> i32 {
    // SAFETY: the caller's contract.
    let Some(sub) = (unsafe { sub.as_ref() }) else {
        set_error("NULL subscriber");
        return -1;
    };
    if out.is_null() {
        set_error("NULL output");
        return -1;
    }
    match sub.subscriber.receive() {
        Ok(Some(sample)) => {
            // SAFETY: `out` is valid for a write (the caller's contract); the C struct is this
            // type's layout (ipc-types' c_layout test).
            unsafe { out.write(*sample) };
            1
        }
        Ok(None) => 0,
        Err(e) => {
            set_error(&format!("receiving an odometry state: {e:?}"));
            -1
        }
    }
}

/// Ends the subscription and frees it (NULL is ignored).
///
/// # Safety
/// `sub` comes from [`mems_odometry_subscribe`] and is not used afterwards.
#[unsafe(no_mangle)]
pub unsafe extern "C" fn mems_odometry_unsubscribe(sub: *mut MemsOdometrySubscriber) {
    if !sub.is_null() {
        // SAFETY: made by Box::into_raw in mems_odometry_subscribe, freed once.
        drop(unsafe { Box::from_raw(sub) });
    }
}

/// The message of this thread's last error ("" if none); valid until the next error.
#[unsafe(no_mangle)]
pub extern "C" fn mems_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}
