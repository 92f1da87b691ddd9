"""The wire protocol: key space, messages, the map feed and the document generated from them."""
