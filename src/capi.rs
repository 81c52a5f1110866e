//! The C API declared in `include/gsi.h`: open a file from memory, query its size, render
//! RGBA8 into the caller's buffer at any size.
//!
//! Every entry point catches panics, so none can unwind into C; errors are returned as a
//! status code with a message kept per thread (`gsi_last_error`).

use crate::format::{self, ErrorKind, Header, Limits};
use crate::model::Scene;
use std::cell::RefCell;
use std::ffi::{c_char, CString};
use std::panic::{catch_unwind, AssertUnwindSafe};

/// Status codes. Values 1–13 mirror [`ErrorKind`]; keep in step with `include/gsi.h`.
pub type GsiStatus = i32;
pub const GSI_OK: GsiStatus = 0;
pub const GSI_ERR_NULL_ARGUMENT: GsiStatus = 100;
pub const GSI_ERR_BUFFER_SIZE: GsiStatus = 101;
pub const GSI_ERR_INTERNAL: GsiStatus = 102;

fn status_of(kind: ErrorKind) -> GsiStatus {
    match kind {
        ErrorKind::Io => 1,
        ErrorKind::Truncated => 2,
        ErrorKind::BadSignature => 3,
        ErrorKind::CrcMismatch => 4,
        ErrorKind::UnknownCriticalChunk => 5,
        ErrorKind::BadChunkType => 6,
        ErrorKind::ChunkOrder => 7,
        ErrorKind::MissingChunk => 8,
        ErrorKind::BadChunkLength => 9,
        ErrorKind::UnsupportedVersion => 10,
        ErrorKind::InvalidValue => 11,
        ErrorKind::LimitExceeded => 12,
        ErrorKind::Decompression => 13,
        // A kind newer than this header (`ErrorKind` is non-exhaustive).
        _ => GSI_ERR_INTERNAL,
    }
}

thread_local! {
    static LAST_ERROR: RefCell<CString> = RefCell::new(CString::default());
}

fn set_error(msg: String) {
    let c = CString::new(msg.replace('\0', " ")).unwrap_or_default();
    LAST_ERROR.with(|e| *e.borrow_mut() = c);
}

/// Run `f`, turning errors and panics into a status and a message.
fn guard(f: impl FnOnce() -> Result<(), (GsiStatus, String)>) -> GsiStatus {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(Ok(())) => GSI_OK,
        Ok(Err((code, msg))) => {
            set_error(msg);
            code
        }
        Err(_) => {
            set_error("internal error (panic caught at the C boundary)".into());
            GSI_ERR_INTERNAL
        }
    }
}

fn from_format(e: format::Error) -> (GsiStatus, String) {
    (status_of(e.kind()), e.to_string())
}

/// An opened file: its header and dequantized Gaussians.
pub struct GsiImage {
    header: Header,
    scene: Scene,
}

/// Parse `len` bytes at `data`. On success `*out` owns a handle to free with `gsi_free`.
///
/// # Safety
/// `data` must point to `len` readable bytes (or be null with `len == 0`); `out` must be
/// a valid pointer to write to.
#[no_mangle]
pub unsafe extern "C" fn gsi_open_memory(
    data: *const u8,
    len: usize,
    out: *mut *mut GsiImage,
) -> GsiStatus {
    guard(|| {
        if out.is_null() || (data.is_null() && len != 0) {
            return Err((
                GSI_ERR_NULL_ARGUMENT,
                "null argument to gsi_open_memory".into(),
            ));
        }
        // SAFETY: the caller guarantees `out` is writable.
        unsafe { *out = std::ptr::null_mut() };
        let bytes: &[u8] = if len == 0 {
            &[]
        } else {
            // SAFETY: the caller guarantees `data` points to `len` readable bytes.
            unsafe { std::slice::from_raw_parts(data, len) }
        };
        let file = format::read_file(bytes, Limits::default()).map_err(from_format)?;
        let image = GsiImage {
            header: file.records.header,
            scene: file.records.to_scene(),
        };
        // SAFETY: as above.
        unsafe { *out = Box::into_raw(Box::new(image)) };
        Ok(())
    })
}

/// Free a handle from `gsi_open_memory`. Null is ignored.
///
/// # Safety
/// `image` must be null or a handle not yet freed.
#[no_mangle]
pub unsafe extern "C" fn gsi_free(image: *mut GsiImage) {
    if !image.is_null() {
        // SAFETY: the caller passes a handle made by Box::into_raw and not yet freed.
        let _ = catch_unwind(AssertUnwindSafe(|| drop(unsafe { Box::from_raw(image) })));
    }
}

/// The stored (reference) size and the number of Gaussians.
///
/// # Safety
/// `image` must be a live handle; each output pointer must be null or writable.
#[no_mangle]
pub unsafe extern "C" fn gsi_info(
    image: *const GsiImage,
    width: *mut u32,
    height: *mut u32,
    gaussians: *mut u32,
) -> GsiStatus {
    guard(|| {
        // SAFETY: the caller passes a live handle or null.
        let img =
            unsafe { image.as_ref() }.ok_or((GSI_ERR_NULL_ARGUMENT, "null image".to_string()))?;
        for (ptr, v) in [
            (width, img.header.width),
            (height, img.header.height),
            (gaussians, img.header.count),
        ] {
            if !ptr.is_null() {
                // SAFETY: non-null output pointers are writable by contract.
                unsafe { *ptr = v };
            }
        }
        Ok(())
    })
}

/// Render at `width × height` into `out` (`out_len ≥ width·height·4` bytes), RGBA8,
/// rows top to bottom, alpha 255.
///
/// # Safety
/// `image` must be a live handle and `out` must point to `out_len` writable bytes.
#[no_mangle]
pub unsafe extern "C" fn gsi_render_rgba8(
    image: *const GsiImage,
    width: u32,
    height: u32,
    out: *mut u8,
    out_len: usize,
) -> GsiStatus {
    guard(|| {
        // SAFETY: the caller passes a live handle or null.
        let img =
            unsafe { image.as_ref() }.ok_or((GSI_ERR_NULL_ARGUMENT, "null image".to_string()))?;
        if out.is_null() {
            return Err((GSI_ERR_NULL_ARGUMENT, "null output buffer".into()));
        }
        Limits::default()
            .check_output(width, height)
            .map_err(from_format)?;
        let need = width as usize * height as usize * 4;
        if out_len < need {
            return Err((
                GSI_ERR_BUFFER_SIZE,
                format!("buffer of {out_len} bytes, {need} needed for {width}x{height} RGBA"),
            ));
        }
        let rgba = crate::render::render(&img.scene, width, height)
            .map_err(from_format)?
            .to_rgba8();
        // SAFETY: `out` holds at least `need` writable bytes, checked above.
        unsafe { std::ptr::copy_nonoverlapping(rgba.as_ptr(), out, need) };
        Ok(())
    })
}

/// The message of the last failed call on this thread (empty if none). The pointer stays
/// valid until the next failing call on the same thread.
#[no_mangle]
pub extern "C" fn gsi_last_error() -> *const c_char {
    LAST_ERROR.with(|e| e.borrow().as_ptr())
}
