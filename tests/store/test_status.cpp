// Status: ok() is the query (the spelling of absl and gRPC status types),
// okStatus() the success, and no static member reads like a query. A static
// ok() factory once made `if (!st.ok())` compile and always be false.
#include <clipstream/store/types.h>

#include <gtest/gtest.h>

#include <type_traits>

namespace clipstream {
namespace {

// ok() is a const member function, not a static one: a pointer to it is a
// pointer to member (a static function's would be a plain function pointer).
static_assert(std::is_same_v<decltype(&Status::ok), bool (Status::*)() const>);

TEST(Status, OkIsTheQueryOnTheInstance) {
  const Status failed = Status::error(ErrorCode::kNotFound, "missing.cstore: no such file");
  EXPECT_FALSE(failed.ok());
  EXPECT_FALSE(bool(failed));
  EXPECT_EQ(failed.toString(), "not found: missing.cstore: no such file");
  const Status success = okStatus();
  EXPECT_TRUE(success.ok());
  EXPECT_TRUE(bool(success));
  EXPECT_EQ(success.toString(), "ok");
  EXPECT_TRUE(Status{}.ok());
}

}  // namespace
}  // namespace clipstream
