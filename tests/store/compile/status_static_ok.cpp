// Must not compile: Status::ok() was a static factory, so `if (!st.ok())`
// compiled and was always false (a host then used the store it had failed
// to open). ok() is the query now; a static ok() must not come back.
#include <clipstream/store/types.h>

clipstream::Status open() { return clipstream::Status::ok(); }

int main() { return open().ok() ? 0 : 1; }
