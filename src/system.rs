//! What the operating system tells about this process: CPU time and peak memory, from
//! `getrusage(RUSAGE_SELF)` (`None` where there is no such call).

/// The process's resource usage so far.
#[cfg(unix)]
fn usage() -> Option<libc::rusage> {
    let mut usage = std::mem::MaybeUninit::<libc::rusage>::uninit();
    // SAFETY: getrusage writes the whole struct when it returns 0, and nothing otherwise.
    let status = unsafe { libc::getrusage(libc::RUSAGE_SELF, usage.as_mut_ptr()) };
    (status == 0).then(|| unsafe { usage.assume_init() })
}

/// CPU seconds used by this process so far (user + system, all threads).
#[cfg(unix)]
pub fn cpu_seconds() -> Option<f64> {
    let u = usage()?;
    let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
    Some(seconds(u.ru_utime) + seconds(u.ru_stime))
}

/// Peak resident memory of this process (`ru_maxrss`: kilobytes on Linux, bytes on macOS).
#[cfg(unix)]
pub fn peak_memory_bytes() -> Option<u64> {
    let maxrss = u64::try_from(usage()?.ru_maxrss).ok()?;
    Some(if cfg!(target_os = "macos") { maxrss } else { maxrss * 1024 })
}

#[cfg(not(unix))]
pub fn cpu_seconds() -> Option<f64> {
    None
}

#[cfg(not(unix))]
pub fn peak_memory_bytes() -> Option<u64> {
    None
}

#[cfg(all(test, target_os = "linux"))]
mod tests {
    use super::*;

    /// CPU seconds of this thread alone (Linux's RUSAGE_THREAD), which the process's include.
    fn thread_cpu_seconds() -> f64 {
        let mut u = std::mem::MaybeUninit::<libc::rusage>::uninit();
        assert_eq!(unsafe { libc::getrusage(libc::RUSAGE_THREAD, u.as_mut_ptr()) }, 0);
        let u = unsafe { u.assume_init() };
        let seconds = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        seconds(u.ru_utime) + seconds(u.ru_stime)
    }

    /// A thread that spins for 0.2 CPU seconds adds at least that to the process's CPU time,
    /// and its wall time bounds what it spent (a wrong tick rate would break one or the other).
    #[test]
    fn cpu_seconds_count_this_threads_work() {
        let (process, thread, wall) = (cpu_seconds().unwrap(), thread_cpu_seconds(), std::time::Instant::now());
        let mut x = 1u64;
        while thread_cpu_seconds() - thread < 0.2 {
            for _ in 0..10_000 {
                x = std::hint::black_box(x.wrapping_mul(6364136223846793005).wrapping_add(1));
            }
        }
        let (spent, wall) = (cpu_seconds().unwrap() - process, wall.elapsed().as_secs_f64());
        let own = thread_cpu_seconds() - thread;
        assert!(spent >= own - 1e-3, "the process used {spent} s, this thread alone {own} s");
        assert!(own <= wall + 1e-2, "this thread used {own} CPU seconds in {wall} s of wall time");
    }

    /// Touching 64 MiB raises the peak to at least that.
    #[test]
    fn peak_memory_counts_touched_pages() {
        let size = 64 << 20;
        let block = std::hint::black_box(vec![1u8; size]);
        let peak = peak_memory_bytes().unwrap();
        assert!(peak >= size as u64, "peak {peak} bytes after touching {size}");
        assert!(peak < 1 << 40, "peak {peak} bytes");
        drop(block);
    }
}
