//! For the tests that run the server out of file descriptors (issue 29: `ulimit -n 64`),
//! in this crate's unit tests and its integration tests alike. Hidden from the docs,
//! not an API.

/// Sets this process's soft limit of open descriptors (at most the hard limit) and
/// returns the old one. `0` makes every new descriptor fail with `EMFILE`, whatever
/// the numbers of the open ones.
pub fn set_nofile(soft: u64) -> u64 {
    let mut r = libc::rlimit {
        rlim_cur: 0,
        rlim_max: 0,
    };
    // SAFETY: getrlimit and setrlimit on a local struct.
    unsafe {
        if libc::getrlimit(libc::RLIMIT_NOFILE, &mut r) != 0 {
            return 0;
        }
        let old = r.rlim_cur;
        r.rlim_cur = soft.min(r.rlim_max);
        libc::setrlimit(libc::RLIMIT_NOFILE, &r);
        old
    }
}
