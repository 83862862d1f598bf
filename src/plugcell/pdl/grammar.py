"""The lark grammar of the robot language (LALR(1), newline-terminated statements).

Kept in Python (not a ``.lark`` file) so that it ships with the package whatever
the install mode.  Keywords are case-insensitive and reserved; identifiers are
case-insensitive too (resolved by the checker).  ``--`` starts a comment.
Statements end at the end of a line; inside parentheses or brackets a line may
break after ``(``, ``[`` or ``,`` (see :class:`~.parser.ContinuationLines`).
"""

GRAMMAR = r"""
start: _NL? module

module: "PROGRAM"i NAME prog_attrs _NL decl* main_body "END"i NAME _NL?
prog_attrs: (prog_attr ("," prog_attr)*)?
prog_attr: NAME ("=" expr)?
main_body: ("BEGIN"i _NL? block)?

?decl: var_section | const_section | import_decl | routine
var_section: "VAR"i _NL? var_decl*
var_decl: name_list ":" type var_attr* _NL
name_list: NAME ("," NAME)*
var_attr: "EXPORTED"i "FROM"i NAME  -> exported_from
        | "EXPORTED"i               -> exported
        | NAME                      -> attr_name
const_section: "CONST"i _NL? const_decl*
const_decl: NAME "=" expr _NL
import_decl: "IMPORT"i STRING _NL

routine: "ROUTINE"i NAME params return_type routine_rest
params: ("(" (param_group ((","|";") param_group)*)? ")")?
param_group: name_list ":" type
return_type: (":" type)?
routine_rest: "EXPORTED"i "FROM"i NAME _NL     -> routine_extern
            | _NL routine_item* "END"i NAME _NL -> routine_body
?routine_item: var_kw | var_decl | begin_kw | stmt
var_kw: "VAR"i _NL?
begin_kw: "BEGIN"i _NL?

?type: "INTEGER"i                          -> t_integer
     | "REAL"i                             -> t_real
     | "BOOLEAN"i                          -> t_boolean
     | "STRING"i ("[" dim "]")?            -> t_string
     | "POSITION"i                         -> t_position
     | "JOINTPOS"i                         -> t_jointpos
     | "VECTOR"i                           -> t_vector
     | "ARRAY"i "[" dim ("," dim)* "]" "OF"i type -> t_array
!dim: INT | "*"

block: stmt*
?stmt: simple_stmt _NL
     | if_stmt
     | for_stmt
     | while_stmt
     | repeat_stmt
     | select_stmt

?simple_stmt: assign
            | call_stmt
            | move_to
            | move_joint
            | move_linear
            | move_relative
            | write_stmt
            | wait_stmt
            | delay_stmt
            | return_stmt
            | deactivate_stmt

assign: designator ":=" expr
call_stmt: NAME ("(" args? ")")?
move_to: "MOVE"i "TO"i expr tracking?
move_joint: "MOVE"i "JOINT"i "TO"i expr tracking?
move_linear: "MOVE"i "LINEAR"i "TO"i expr tracking?
tracking: "WITH"i "TRACKING"i NAME?
move_relative: "MOVE"i "RELATIVE"i expr "IN"i NAME
write_stmt: "WRITE"i NAME "(" (write_item ("," write_item)*)? ")"
write_item: expr ("::" expr ("::" expr)?)?
wait_stmt: "WAIT"i "FOR"i expr ("TIMEOUT"i expr)?
delay_stmt: "DELAY"i expr
return_stmt: "RETURN"i expr?
deactivate_stmt: "DEACTIVATE"i name_list?

if_stmt: "IF"i expr "THEN"i _NL? block else_part? "ENDIF"i _NL
else_part: "ELSE"i _NL? block
for_stmt: "FOR"i NAME ":=" expr for_dir expr for_step "DO"i _NL? block "ENDFOR"i _NL
for_dir: TO | DOWNTO
TO: "TO"i
DOWNTO: "DOWNTO"i
for_step: ("STEP"i expr)?
while_stmt: "WHILE"i expr "DO"i _NL? block "ENDWHILE"i _NL
repeat_stmt: "REPEAT"i _NL? block "UNTIL"i expr _NL
select_stmt: "SELECT"i expr "OF"i _NL case_clause+ select_else? "ENDSELECT"i _NL
case_clause: "CASE"i "(" expr ("," expr)* ")" ":" _NL? block
select_else: "ELSE"i ":" _NL? block

?expr: sum
     | sum comp_op sum        -> binary
?sum: term
    | sum add_op term         -> binary
?term: factor
     | term mul_op factor     -> binary
?factor: primary
       | unary_op factor      -> unary
?primary: INT                 -> int_lit
        | REAL                -> real_lit
        | STRING              -> str_lit
        | "TRUE"i             -> true_lit
        | "FALSE"i            -> false_lit
        | NAME "(" args? ")"  -> call
        | designator
        | "(" expr ")"
?designator: NAME                                  -> name
           | designator "[" expr ("," expr)* "]"   -> index
           | designator "." NAME                   -> field
args: expr ("," expr)*

!comp_op: "=" | "<>" | "<" | "<=" | ">" | ">="
!add_op: "+" | "-" | "OR"i | "XOR"i
!mul_op: "*" | "/" | "DIV"i | "MOD"i | "AND"i
!unary_op: "-" | "+" | "NOT"i

NAME: /\$?[A-Za-z_][A-Za-z0-9_]*/
REAL: /(\d+\.\d*|\.\d+)([eE][+-]?\d+)?|\d+[eE][+-]?\d+/
INT: /\d+/
STRING: /'(?:[^'\n]|'')*'/
_NL: /(\r?\n[\t \f\r]*(--[^\n]*)?)+/
COMMENT: /--[^\n]*/
%ignore /[ \t\f\r]+/
%ignore COMMENT
"""
