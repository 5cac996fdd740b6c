//! A connection whose writes may wait for the client only so long. hyper has no write timeout:
//! a client that requests a file and never reads it leaves hyper waiting on a full socket
//! buffer for ever, holding the connection's slot (80 such clients once took every slot of a
//! daemon capped at 80, and every `/health` probe was refused). Here a write that has waited
//! `stall` for the client fails the connection with `TimedOut`; a write that makes progress,
//! however little, starts the clock again.

use std::future::Future;
use std::io;
use std::pin::Pin;
use std::task::{Context, Poll};
use std::time::Duration;
use tokio::io::{AsyncRead, AsyncWrite, ReadBuf};
use tokio::time::{Instant, Sleep};

pub struct StallGuarded<T> {
    inner: T,
    stall: Duration,
    timer: Pin<Box<Sleep>>,
    /// Whether a write is waiting (the timer runs).
    waiting: bool,
}

impl<T> StallGuarded<T> {
    pub fn new(inner: T, stall: Duration) -> Self {
        Self {
            inner,
            stall,
            timer: Box::pin(tokio::time::sleep(stall)),
            waiting: false,
        }
    }

    /// Passes on what a write attempt gave; a `Pending` starts (or keeps) the stall clock, and
    /// a clock that ran out turns it into `TimedOut`.
    fn watch<R>(
        &mut self,
        cx: &mut Context<'_>,
        attempt: Poll<io::Result<R>>,
    ) -> Poll<io::Result<R>> {
        match attempt {
            Poll::Ready(r) => {
                self.waiting = false;
                Poll::Ready(r)
            }
            Poll::Pending => {
                if !self.waiting {
                    self.waiting = true;
                    self.timer.as_mut().reset(Instant::now() + self.stall);
                }
                match self.timer.as_mut().poll(cx) {
                    Poll::Ready(()) => Poll::Ready(Err(io::Error::new(
                        io::ErrorKind::TimedOut,
                        format!(
                            "the client read nothing for {} s: closing",
                            self.stall.as_secs()
                        ),
                    ))),
                    Poll::Pending => Poll::Pending,
                }
            }
        }
    }
}

impl<T: AsyncRead + Unpin> AsyncRead for StallGuarded<T> {
    fn poll_read(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &mut ReadBuf<'_>,
    ) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_read(cx, buf)
    }
}

impl<T: AsyncWrite + Unpin> AsyncWrite for StallGuarded<T> {
    fn poll_write(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        buf: &[u8],
    ) -> Poll<io::Result<usize>> {
        let attempt = Pin::new(&mut self.inner).poll_write(cx, buf);
        self.watch(cx, attempt)
    }

    fn poll_write_vectored(
        mut self: Pin<&mut Self>,
        cx: &mut Context<'_>,
        bufs: &[io::IoSlice<'_>],
    ) -> Poll<io::Result<usize>> {
        let attempt = Pin::new(&mut self.inner).poll_write_vectored(cx, bufs);
        self.watch(cx, attempt)
    }

    fn is_write_vectored(&self) -> bool {
        self.inner.is_write_vectored()
    }

    fn poll_flush(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        let attempt = Pin::new(&mut self.inner).poll_flush(cx);
        self.watch(cx, attempt)
    }

    fn poll_shutdown(mut self: Pin<&mut Self>, cx: &mut Context<'_>) -> Poll<io::Result<()>> {
        Pin::new(&mut self.inner).poll_shutdown(cx)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::{AsyncReadExt, AsyncWriteExt};

    #[tokio::test(start_paused = true)]
    async fn a_reader_that_stops_fails_the_write_and_one_that_reads_does_not() {
        // A 64-byte pipe: the writer fills it at once and then waits on the reader.
        let (ours, _theirs) = tokio::io::duplex(64);
        let mut guarded = StallGuarded::new(ours, Duration::from_secs(5));
        let e = guarded.write_all(&[7u8; 1024]).await.unwrap_err();
        assert_eq!(e.kind(), io::ErrorKind::TimedOut);

        let (ours, mut reader) = tokio::io::duplex(64);
        let mut guarded = StallGuarded::new(ours, Duration::from_secs(5));
        let read = tokio::spawn(async move {
            let mut got = Vec::new();
            let mut piece = [0u8; 16];
            // Slow, but never silent for 5 s.
            while got.len() < 1024 {
                tokio::time::sleep(Duration::from_secs(1)).await;
                let n = reader.read(&mut piece).await.unwrap();
                got.extend_from_slice(&piece[..n]);
            }
            got.len()
        });
        guarded.write_all(&[7u8; 1024]).await.unwrap();
        assert_eq!(read.await.unwrap(), 1024);
    }
}
