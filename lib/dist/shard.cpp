#include "dist/shard.hpp"

#include <algorithm>
#include <cstring>
#include <numeric>

#include "core/error.hpp"
#include "dist/communicator.hpp"

namespace th::dist {

std::vector<std::vector<int64_t>> balance(const std::vector<std::vector<int64_t>>& groups,
                                          const std::vector<double>& cost, int ranks) {
  if (ranks < 1) fail("cannot split work over ", ranks, " ranks");
  if (cost.size() != groups.size())
    fail("balance: ", groups.size(), " groups but ", cost.size(), " costs");
  std::vector<size_t> order(groups.size());
  std::iota(order.begin(), order.end(), size_t(0));
  std::stable_sort(order.begin(), order.end(),
                   [&](size_t a, size_t b) { return cost[a] > cost[b]; });
  std::vector<double> load(size_t(ranks), 0.0);
  std::vector<std::vector<int64_t>> out(static_cast<size_t>(ranks));
  for (const size_t g : order) {
    const auto r = size_t(std::min_element(load.begin(), load.end()) - load.begin());
    load[r] += cost[g];
    out[r].insert(out[r].end(), groups[g].begin(), groups[g].end());
  }
  for (auto& items : out) std::sort(items.begin(), items.end());
  return out;
}

void broadcast_items(Communicator& comm, std::vector<int64_t>& items, const std::string& what) {
  Record list;
  list.put(int64_t(items.size()));
  for (const int64_t k : items) list.put(k);
  std::string bytes = list.bytes();
  comm.broadcast(bytes, what);
  Record received(bytes);
  items.assign(size_t(received.int64("item count")), 0);
  for (auto& k : items) k = received.int64("item");
}

Record& Record::put(int64_t v) {
  bytes_.append(reinterpret_cast<const char*>(&v), sizeof v);
  return *this;
}

Record& Record::put(double v) {
  bytes_.append(reinterpret_cast<const char*>(&v), sizeof v);
  return *this;
}

Record& Record::put(const std::string& s) {
  put(int64_t(s.size()));
  bytes_ += s;
  return *this;
}

void Record::read(void* out, size_t n, const char* what) {
  if (bytes_.size() - pos_ < n)
    fail("a result record ends after ", bytes_.size(), " bytes, before its ", what);
  std::memcpy(out, bytes_.data() + pos_, n);
  pos_ += n;
}

int64_t Record::int64(const char* what) {
  int64_t v = 0;
  read(&v, sizeof v, what);
  return v;
}

double Record::number(const char* what) {
  double v = 0;
  read(&v, sizeof v, what);
  return v;
}

std::string Record::text(const char* what) {
  const int64_t n = int64(what);
  if (n < 0 || uint64_t(n) > bytes_.size() - pos_)
    fail("a result record's ", what, " claims ", n, " bytes where ", bytes_.size() - pos_,
         " are left");
  std::string s(bytes_.data() + pos_, size_t(n));
  pos_ += size_t(n);
  return s;
}

}  // namespace th::dist
