//! Real-time scheduling for the threads that must not wait behind the desktop (the virtual
//! device's 1 kHz loop, the device link's heartbeat thread). A leaf module: it imports
//! nothing from the crate.

/// Asks for the real-time FIFO scheduling class for the calling thread (Linux; needs
/// CAP_SYS_NICE or an rtprio limit); returns whether it was granted. The thread sleeps between
/// ticks, so it cannot starve the machine.
pub(crate) fn request() -> bool {
    #[cfg(target_os = "linux")]
    {
        let param = libc::sched_param { sched_priority: 20 };
        // SAFETY: `pthread_self()` is the calling thread and `param` a valid sched_param.
        unsafe { libc::pthread_setschedparam(libc::pthread_self(), libc::SCHED_FIFO, &param) == 0 }
    }
    #[cfg(not(target_os = "linux"))]
    {
        false
    }
}
