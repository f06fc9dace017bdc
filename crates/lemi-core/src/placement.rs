//! Layer placement: the error metric of GI 2002 sec. 4 and TR-186-2-02-04 sec. 2.
