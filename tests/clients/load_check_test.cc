// The load tester's journal check on made-up histories: it must name every
// kind of loss, duplicate and reorder, and pass a clean one.
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "clients/load/load.h"

namespace dynsolid::load {
namespace {

using ::testing::ElementsAre;
using ::testing::HasSubstr;
using ::testing::IsEmpty;

client::CommandRecord Acked(uint64_t seq, int64_t step, int code = 0) {
  client::CommandRecord r;
  r.seq = seq;
  r.command.mutable_set_gravity()->set_z(-1);
  r.answered = true;
  r.reply.set_seq(seq);
  r.reply.set_applied_step(step);
  r.reply.set_code(code);
  return r;
}

CommandLog Log(const std::vector<std::pair<uint64_t, int>>& seq_code) {
  CommandLog log;
  for (const auto& [seq, code] : seq_code) {
    CommandLogEntry* e = log.add_entries();
    e->set_client_id("c");
    e->set_seq(seq);
    e->set_code(code);
    e->set_kind("set_gravity");
  }
  return log;
}

TEST(LoadCheckTest, ACleanHistoryPasses) {
  const std::vector<client::CommandRecord> r = {Acked(1, 0), Acked(2, 3, 5), Acked(3, 3)};
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}, {2, 5}, {3, 0}})), IsEmpty());
}

TEST(LoadCheckTest, AnUnansweredCommandMayBeAbsentOrPresent) {
  std::vector<client::CommandRecord> r = {Acked(1, 0), Acked(2, 1)};
  r[1].answered = false;
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}})), IsEmpty());
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}, {2, 0}})), IsEmpty());
}

TEST(LoadCheckTest, NamesALostCommand) {
  const std::vector<client::CommandRecord> r = {Acked(1, 0), Acked(2, 4), Acked(3, 4)};
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}, {3, 0}})),
              ElementsAre(HasSubstr("c seq 2 (set_gravity): acknowledged at step 4 but not in "
                                    "the journal (lost)")));
}

TEST(LoadCheckTest, NamesADuplicateAndAReorder) {
  const std::vector<client::CommandRecord> r = {Acked(1, 0), Acked(2, 0), Acked(3, 0)};
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}, {2, 0}, {2, 0}, {3, 0}})),
              ElementsAre(HasSubstr("c seq 2 (set_gravity): applied twice"),
                          HasSubstr("seq 2 (set_gravity): applied after seq 2 (out of order)")));
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}, {3, 0}, {2, 0}})),
              ElementsAre(HasSubstr("c seq 2 (set_gravity): applied after seq 3 (out of order)")));
}

TEST(LoadCheckTest, NamesAnUnknownEntryAStatusMismatchAndARefusalForGood) {
  std::vector<client::CommandRecord> r = {Acked(1, 0), Acked(2, 0, 0), Acked(3, -1, 11)};
  r[2].reply.set_message("seq: 3 is not above ...");
  EXPECT_THAT(CheckAgainstJournal("c", r, Log({{1, 0}, {2, 5}, {9, 0}})),
              ElementsAre(HasSubstr("c seq 2 (set_gravity): answered OK, journaled NOT_FOUND"),
                          HasSubstr("c seq 9 (set_gravity): in the journal but never sent"),
                          HasSubstr("c seq 3: never applied: OUT_OF_RANGE: seq: 3 is not above")));
}

}  // namespace
}  // namespace dynsolid::load
