// Writing a cache file (a factor, a compliance operator) so that no reader ever sees half of
// it: the bytes go to a temporary of this call's own ("<file>.tmp.<pid>.<n>": two servers, or two
// threads of one, filling the same key never share one), and the temporary is renamed over the
// file only when every byte was written (rename is atomic: a reader opens the old whole file or
// the new whole file; two writers of one key both rename, the last one's stays). A cache that cannot be written (disk full, read-only folder) is said once
// on stderr, naming the owner and the file, and the caller goes on without it: a cache is an
// optimisation, never a reason to stop a session.
#pragma once

#include <functional>
#include <ostream>
#include <string>

namespace neurosim::common {

// Creates file's folder if missing, calls write(out) on the temporary, checks the stream and
// renames. Returns true when the file is in place. On failure writes "<owner>: could not write
// <what> <file>: <reason> (continuing without it)" to stderr, removes the temporary and
// returns false.
bool write_cache_file(const std::string& file, const std::string& owner, const std::string& what,
                      const std::function<void(std::ostream&)>& write);

}  // namespace neurosim::common
