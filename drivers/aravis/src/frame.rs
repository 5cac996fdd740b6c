//! One Aravis buffer into one `Frame`, or the reason it is not one.

use crate::unpack::{bytes_per_pixel, from_pfnc, unpack_mono};
use aravis::glib::translate::ToGlibPtr;
use aravis::{Buffer, BufferPayloadType, BufferStatus};
use ffdic_hw::Frame;
use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Why a buffer holds no usable frame. Any of these counts as a failed frame.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum BadBuffer {
    #[error("buffer status {0:?}")]
    Status(BufferStatus),
    #[error("payload {0:?} is not an image")]
    Payload(BufferPayloadType),
    #[error("pixel format 0x{0:08x} is not Mono8/10/12/16")]
    Format(u32),
    #[error(transparent)]
    Unpack(#[from] crate::unpack::UnpackError),
}

/// The frame in `buffer`. The status is checked before anything else is read: the data of a
/// failed buffer is undefined and Aravis warns (GLib criticals) on some accessors.
pub(crate) fn frame_from_buffer(buffer: &Buffer) -> Result<Frame, BadBuffer> {
    let status = buffer.status();
    if status != BufferStatus::Success {
        return Err(BadBuffer::Status(status));
    }
    let payload = buffer.payload_type();
    if !matches!(
        payload,
        BufferPayloadType::Image | BufferPayloadType::ExtendedChunkData
    ) {
        return Err(BadBuffer::Payload(payload));
    }
    let pfnc = buffer.image_pixel_format().raw();
    let format = from_pfnc(pfnc).ok_or(BadBuffer::Format(pfnc))?;
    let width = buffer.image_width().max(0) as usize;
    let height = buffer.image_height().max(0) as usize;
    let (x_padding, _) = buffer.image_padding();
    let stride_bytes = width * bytes_per_pixel(format) + x_padding.max(0) as usize;
    let data = {
        let mut size = 0usize;
        // SAFETY: the pointer and size come from Aravis for this buffer, which `buffer` keeps
        // alive (and out of the stream's pool) for the whole borrow; the bytes are copied out
        // by `unpack_mono` before the buffer goes back.
        let bytes = unsafe {
            let ptr = aravis_sys::arv_buffer_get_image_data(buffer.to_glib_none().0, &mut size);
            if ptr.is_null() {
                &[][..]
            } else {
                std::slice::from_raw_parts(ptr as *const u8, size)
            }
        };
        unpack_mono(bytes, width, height, format, stride_bytes)?
    };
    let device_ns = buffer.timestamp();
    let system_ns = buffer.system_timestamp();
    Ok(Frame {
        width,
        height,
        bit_depth: format.bit_depth(),
        data,
        frame_id: buffer.frame_id(),
        device_timestamp_ns: (device_ns != 0).then_some(device_ns),
        host_timestamp: match system_ns {
            0 => SystemTime::now(),
            ns => UNIX_EPOCH + Duration::from_nanos(ns),
        },
    })
}
