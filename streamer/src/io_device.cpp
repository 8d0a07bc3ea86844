#include "io_device.h"

namespace clipstream {

std::shared_ptr<IoTicket> IoDevice::issue(const LayerTile& key, uint64_t due_frame, bool reread) {
  auto ticket = std::make_shared<IoTicket>();
  ticket->key = key;
  ticket->due_frame = due_frame;
  ticket->reread = reread;
  m_issued.push_back(ticket);
  m_work.push_back(ticket);
  return ticket;
}

std::shared_ptr<IoTicket> IoDevice::takeWork() {
  if (m_work.empty()) return nullptr;
  std::shared_ptr<IoTicket> ticket = std::move(m_work.front());
  m_work.pop_front();
  return ticket;
}

void IoDevice::finished(IoTicket& ticket) {
  ticket.done = true;
  m_done_cv.notify_all();
}

std::shared_ptr<IoTicket> IoDevice::nextDue(std::unique_lock<std::mutex>& lock, uint64_t frame, bool all) {
  if (m_issued.empty() || !(all || m_issued.front()->due_frame <= frame)) return nullptr;
  std::shared_ptr<IoTicket> ticket = std::move(m_issued.front());
  m_issued.pop_front();
  m_done_cv.wait(lock, [&] { return ticket->done; });
  return ticket;
}

}  // namespace clipstream
