//! The cause of a failed file operation in words a person can act on: what the operating system
//! said and the name of its error (`no space left on device (ENOSPC)`), for the messages of the
//! trace exports and of `runs prune`.

use std::io;

use rustix::io::Errno;

/// The operating system's errors a write or a removal meets most, with their names and meaning.
const NAMED: [(Errno, &str, &str); 16] = [
    (Errno::NOSPC, "ENOSPC", "no space left on device"),
    (Errno::DQUOT, "EDQUOT", "disk quota exceeded"),
    (Errno::ROFS, "EROFS", "read-only file system"),
    (Errno::ACCESS, "EACCES", "permission denied"),
    (Errno::PERM, "EPERM", "operation not permitted"),
    (Errno::IO, "EIO", "input/output error"),
    (Errno::FBIG, "EFBIG", "file too large"),
    (Errno::BUSY, "EBUSY", "device or resource busy"),
    (Errno::NOTEMPTY, "ENOTEMPTY", "directory not empty"),
    (Errno::NOENT, "ENOENT", "no such file or directory"),
    (Errno::EXIST, "EEXIST", "file exists"),
    (Errno::XDEV, "EXDEV", "cross-device link"),
    (Errno::NOTDIR, "ENOTDIR", "not a directory"),
    (Errno::ISDIR, "EISDIR", "is a directory"),
    (Errno::MFILE, "EMFILE", "too many open files"),
    (Errno::NAMETOOLONG, "ENAMETOOLONG", "file name too long"),
];

/// `e` as `<meaning> (<error name>)`, e.g. `no space left on device (ENOSPC)`; another error
/// of the operating system as its own text with its number, any other error as its text.
pub fn describe(e: &io::Error) -> String {
    let Some(code) = e.raw_os_error() else {
        // An error of the operating system wrapped in another (`io::Error::other(e)`).
        return match e
            .get_ref()
            .and_then(|inner| inner.downcast_ref::<io::Error>())
        {
            Some(inner) => describe(inner),
            None => e.to_string(),
        };
    };
    match NAMED
        .iter()
        .find(|(errno, ..)| errno.raw_os_error() == code)
    {
        Some((_, name, meaning)) => format!("{meaning} ({name})"),
        None => e.to_string(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_full_disk_is_named_enospc_and_other_errors_keep_their_text() {
        let full = io::Error::from_raw_os_error(Errno::NOSPC.raw_os_error());
        assert_eq!(describe(&full), "no space left on device (ENOSPC)");
        let ro = io::Error::from_raw_os_error(Errno::ROFS.raw_os_error());
        assert_eq!(describe(&ro), "read-only file system (EROFS)");
        let wrapped = io::Error::other(io::Error::from_raw_os_error(Errno::NOSPC.raw_os_error()));
        assert_eq!(describe(&wrapped), "no space left on device (ENOSPC)");
        let other = io::Error::other("a broken pipe of our own");
        assert_eq!(describe(&other), "a broken pipe of our own");
        let unlisted = io::Error::from_raw_os_error(Errno::NOEXEC.raw_os_error());
        assert!(describe(&unlisted).contains("os error"), "{unlisted}");
    }
}
