"""cbdi scheduler: the BDI part of an agent (beliefs, desires, reactive rules, intentions)."""
