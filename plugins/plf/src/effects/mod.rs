//! Effect blocks of the PLF vocabulary.
