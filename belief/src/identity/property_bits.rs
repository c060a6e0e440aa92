pub struct BitCode; pub struct PropertyBitsFilter;
