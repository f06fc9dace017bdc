//! Compression stages of GI 2002 sec. 5, one file per stage.
