# The teahouse's dialogue language: what the owner writes on the left, the Drools text on the right.
# Each line: [condition] or [consequence], then the phrase = what it stands for.
# {name} is filled in from the rule; {name:\d+} accepts digits only.
# A line that starts with "- " adds a constraint to the fact described on the line above.
# Longer phrases come before shorter ones that start the same way: the first match wins.
#
# In "The customer says", DRINK stands for any drink of the menu and NUMBER for any number; the
# words may come anywhere in what the customer says, with anything before or after them. Write the
# words in lower case letters, digits and apostrophes, separated by spaces. The same sentences make
# the grammar the speech recogniser listens with.

# --- 1. Understanding: what the customer means ----------------------------------------------
[condition][]The customer says "{words}"=$u: Utterance(intent == null, shape matches "(?i)(.* )?{words}( .*)?")
[condition][]The customer said something nobody understood=$u: Utterance(intent == null)
[consequence][]The customer means "{intent}"=modify($u) \{ setIntent("{intent}") \};
[consequence][]The words carry no meaning=// recognised and ignored: they only make the customer polite

# --- 2. The dialogue: the order's slots and the conversation's state ----------------------
[condition][]The customer asks for something=$u: Utterance(intent in ("order", "correct"), handled == false)
[condition][]The customer's words mean "{intent}"=$u: Utterance(intent == "{intent}", handled == false)
[condition][]- and name a drink=drink != ""
[condition][]- and name a number=count > 0
[condition][]- and name nothing more=drink == "", count == 0
[condition][]The conversation is going on=$c: Conversation(id == $u.conversation, state in ("ordering", "confirming"))
[condition][]The conversation is "{state}"=$c: Conversation(id == $u.conversation, state == "{state}")
[condition][]- with a drink and a number of cups=drink != "", cups > 0
[condition][]- with a drink=drink != ""
[condition][]- without a drink=drink == ""
[condition][]- without a number of cups=cups == 0
[condition][]The customer has said nothing for {n:\d+} seconds=$s: Silence(seconds >= {n}) $c: Conversation(id == $s.conversation, state in ("ordering", "confirming"))
[consequence][]The order's drink is the one named=modify($c) \{ setDrink($u.getDrink()) \}; modify($u) \{ setDrink("") \};
[consequence][]The order's cups are the number named=modify($c) \{ setCups($u.getCount()) \}; modify($u) \{ setCount(0) \};
[consequence][]The order is forgotten=modify($c) \{ setDrink(""), setCups(0) \};
[consequence][]The conversation becomes "{state}"=modify($c) \{ setState("{state}") \};
[consequence][]The turn is handled=modify($u) \{ setHandled(true) \};
[consequence][]The order goes to the kitchen=actions.call("order", "conversation", $c.getId(), "table", $c.getTable(), "drink", $c.getDrink(), "cups", $c.getCups());

# --- 3. Answers: what Pepper says ----------------------------------------------------------
# In what Pepper says, {drink} is the drink ordered, {drinks} the same with the plural when
# more than one cup is ordered, and {cups} the number of cups.
[condition][]Pepper is to answer words that mean "{intent}"=$u: Utterance(handled == true, answered == false, intent == "{intent}")
[condition][]Pepper is to answer=$u: Utterance(handled == true, answered == false)
[condition][]The conversation has timed out=$s: Silence() $c: Conversation(id == $s.conversation, state == "ended")
[consequence][]Pepper says "{text}"=actions.say("pepper", "{text}");
[consequence][]Pepper has answered=modify($u) \{ setAnswered(true) \};
[consequence][]The silence is over=retract($s);
