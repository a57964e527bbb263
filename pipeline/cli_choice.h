// Options whose value is one of a few words, parsed into an enum at the CLI boundary: anything else
// is CLI11's "not in {...}" error (exit 2), and the rest of perf sees only the enum.
#pragma once

#include <CLI/CLI.hpp>
#include <string>
#include <utility>
#include <vector>

namespace perf {

template <typename E>
CLI::Option* AddChoiceOption(CLI::App* cmd, const std::string& name, E* value,
                             std::vector<std::pair<std::string, E>> words, const std::string& help) {
  std::vector<std::string> keys;
  std::string current;
  for (const auto& [word, e] : words) {
    keys.push_back(word);
    if (e == *value) current = word;
  }
  CLI::Option* option = cmd->add_option_function<std::string>(
      name,
      [value, words](const std::string& s) {
        for (const auto& [word, e] : words) {
          if (word == s) *value = e;
        }
      },
      help);
  return option->check(CLI::IsMember(keys))->default_str(current);
}

}  // namespace perf
