// XML text and attribute escaping, shared by the X3D export, the XDMF
// sidecar writer and the trade study's SVG plot (all link tissue_util).
#pragma once

#include <string>
#include <string_view>

namespace tissue::util {

// `s` as XML 1.0 character data that is well-formed wherever it goes: in
// element text and in attributes quoted with either quote.
// - & < > ' " become their entities;
// - tab, newline and carriage return become &#9; &#10; &#13; (an attribute
//   value's parser would turn them into spaces, and a CR would be lost);
// - what XML 1.0 does not allow at all (the other C0 control characters,
//   U+FFFE, U+FFFF) and bytes that are not UTF-8 become U+FFFD, one per
//   offending byte or character.
// A title taken from a file name ($'a\x01.h5') made ill-formed XML before.
std::string escape_xml(std::string_view s);

}  // namespace tissue::util
