pub mod table51;
