#pragma once
// Splitting a list of work items (test views, video frames) over the ranks, and the small
// binary records ranks send their results in.

#include <cstdint>
#include <string>
#include <vector>

namespace th::dist {

class Communicator;

// Items in groups that must stay on one rank (the views of one frame share its preparation),
// each group with an estimated cost. Returns, for each of `ranks` ranks, the items it takes in
// ascending order: whole groups, largest first to the least loaded rank (ties to the lower
// rank), so every rank's estimated cost is within one group's of the others'. Deterministic.
std::vector<std::vector<int64_t>> balance(const std::vector<std::vector<int64_t>>& groups,
                                          const std::vector<double>& cost, int ranks);

// Rank 0's `items` on every rank (what is left to do after a resume, which rank 0 alone reads),
// `what` naming them in an error.
void broadcast_items(Communicator& comm, std::vector<int64_t>& items, const std::string& what);

// A record of numbers and byte strings, written and read back in the same order.
class Record {
 public:
  Record() = default;
  explicit Record(std::string bytes) : bytes_(std::move(bytes)) {}

  Record& put(int64_t v);
  Record& put(double v);
  Record& put(const std::string& s);
  const std::string& bytes() const { return bytes_; }

  // Read in the order written; throws th::Error naming `what` when the record ends early.
  int64_t int64(const char* what);
  double number(const char* what);
  std::string text(const char* what);

 private:
  void read(void* out, size_t n, const char* what);
  std::string bytes_;
  size_t pos_ = 0;
};

}  // namespace th::dist
